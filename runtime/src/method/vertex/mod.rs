//! The vertex methods (static average, Kontkanen & Aila's vertex-linear,
//! Kirk & Arikan's vertex-clustered) as an engine evaluates them: the
//! per-vertex linear form ([`form`]) every one of them reduces to, and the
//! eigen-AO basis's per-pose step ([`basis`]). The per-pose weights of
//! each method and the codec are still in aobake-core (issue 28 moves them
//! here).

pub mod basis;
pub mod form;

pub use basis::Basis;
pub use form::{Block, Coefficients, FormRef, LinearForm, SparseForm};
