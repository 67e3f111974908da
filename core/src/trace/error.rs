//! Why tracing cannot run.

/// Invalid tracing input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TraceError {
    /// A parameter or the geometry is unusable; the message names it.
    #[error("{0}")]
    Invalid(String),
}
