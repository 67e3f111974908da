//! # aobake-worker
//!
//! The worker process will own everything that turns one of core's pure job
//! functions into a running, interruptible process: the lease loop over the
//! server's HTTP job API, heartbeats off the compute thread, checkpoint upload
//! and resume, cancellation, and wgpu preview rendering (DESIGN §2, §8).
//! It holds no queue state and never talks to the database.
//!
//! Today it holds the GPU side ([`gpu`]): a wgpu device on whatever adapter
//! the machine has, and the run-time evaluation of the vertex methods in
//! WGSL, checked against core's CPU evaluation. The job loop arrives with
//! the server's job API.

pub mod gpu;
