//! # aobake-e2e
//!
//! End-to-end tests will live here: a `TestEnv` that owns a temporary
//! directory, starts the real `aobake` server on port 0 and real worker
//! processes, and kills them on drop (STYLE.md, "Tests").
//!
//! The server and the workers do not exist yet; the command-line tool's tests
//! live with it in `server/tests/`.
