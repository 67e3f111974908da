//! # aobake-server
//!
//! The `aobake` binary. Today it is the command-line front of core:
//! [`cli`] loads characters and clips from files (the only place where
//! upload names become file-system paths), inspects them and writes posed
//! meshes. The HTTP service (axum API, planner, job queue on SQLite or
//! PostgreSQL, blob store, dashboard) will live beside it, in `routes/`,
//! `store/` and `blobs/` (DESIGN §2).

pub mod cli;
