//! The vertex methods (static average, Kontkanen & Aila's vertex-linear,
//! Kirk & Arikan's vertex-clustered) as an engine evaluates them: the
//! per-vertex linear form ([`form`]) every one of them reduces to. The
//! per-pose weights, the basis and the codec are still in aobake-core
//! (issue 28 moves them here).

pub mod form;

pub use form::{Block, Coefficients, FormRef, LinearForm, SparseForm};
