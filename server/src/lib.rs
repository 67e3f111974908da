//! # aobake-server
//!
//! The `aobake` binary: the HTTP service and the command-line tools.
//!
//! * [`app`]: the axum application (layers, [`app::app`]) over `routes`
//!   (one file per resource: uploads, bakes, the worker protocol, assets,
//!   system), all reading the shared [`state::AppState`].
//! * [`store`]: metadata and the job queue behind one trait (SQLite, the
//!   embedded default). [`blobs`]: content-addressed bytes behind another
//!   (local disk).
//! * [`auth`]: bearer tokens with scopes, stored hashed. [`error`]: one
//!   error type, problem+json on the wire.
//! * [`serve`]: `aobake serve`, the API on the embedded defaults with
//!   supervised local worker processes.
//! * `dashboard`: the browser pages at `/` (plain files in the binary),
//!   live over the API's server-sent events.
//! * [`cli`]: every `aobake` command; thin, it parses, calls and prints.
//!
//! A bake's life: `POST /v1/bakes` imports the inputs, plans core's job
//! graph and stores it; workers long-poll `POST /v1/jobs/lease`, run
//! core's job function, upload outputs and checkpoints as blobs and
//! complete with their lease token; `assemble` publishes the asset,
//! `preview` renders its images, the last completion finishes the bake,
//! and `GET /v1/cache/{key}` finds it from then on.
//!
//! **Layers**, bottom up: `store`, `blobs`, `repair`, `error`, `state`, `auth`,
//! `extract`, `dashboard`, `routes`, `openapi`, `app`, `listen`, `demo`,
//! `serve`, `cli`. No file imports one of a higher layer
//! (`python3 tools/import-graph.py server <layers>`). The wire types and
//! the HTTP client are the `aobake-api` crate's.

/// A line of the server's log on stderr: stamped and written at once,
/// as its workers' lines are ([`aobake_worker::say!`]).
macro_rules! log_line {
    ($($arg:tt)*) => {
        aobake_worker::say!($($arg)*)
    };
}

pub mod app;
pub mod auth;
pub mod blobs;
pub mod cli;
mod dashboard;
mod demo;
pub mod error;
mod extract;
pub mod listen;
pub mod openapi;
pub mod repair;
mod routes;
pub mod serve;
pub mod state;
pub mod store;
