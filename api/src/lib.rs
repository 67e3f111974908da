//! aobake's HTTP API as Rust: the wire types ([`types`]) that the server
//! answers with and its clients send, and [`Client`], the one blocking
//! client that the worker and the `aobake` CLI use. It waits out 429s as
//! the server's `Retry-After` asks and turns every error status into a
//! typed [`ApiError`] carrying the problem+json body.
//!
//! It knows nothing of SQL, queues or AO: it is the contract between
//! processes. With the `schema` feature the types also derive their
//! OpenAPI schemas, from which the server writes `api-spec/openapi.yaml`.

pub mod client;
pub mod progress;
#[cfg(feature = "schema")]
pub mod schema;
pub mod types;

pub use client::{ApiError, Client};
pub use types::*;
