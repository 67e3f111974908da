//! # aobake-worker
//!
//! The worker process will own everything that turns one of core's pure job
//! functions into a running, interruptible process: the lease loop over the
//! server's HTTP job API, heartbeats off the compute thread, checkpoint upload
//! and resume, cancellation, and wgpu preview rendering (DESIGN §2, §8).
//!
//! It holds no queue state and never talks to the database. Nothing is here
//! yet: the job API it consumes does not exist so far.
