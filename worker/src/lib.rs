//! # aobake-worker
//!
//! Everything that turns one of core's pure job functions into a running,
//! interruptible process (DESIGN §2, §8). It holds no queue state and
//! never talks to the database: only to the server's HTTP job API.
//!
//! * [`run`] ([`runner`]): the lease loop. Each of `concurrency` threads
//!   long-polls for a job, downloads its inputs and last checkpoint,
//!   runs core's job function on its own (compute) thread while a second
//!   thread heartbeats, uploads checkpoints as the job saves them and its
//!   outputs at the end, and completes with its lease token. SIGTERM stops
//!   leasing at once (an open long poll is abandoned: the server drops it
//!   with its connection); a running job finishes or, past the deadline,
//!   stops at its next checkpoint and gives its lease back.
//! * the HTTP calls: [`aobake_api::Client`].
//! * [`gpu`]: a wgpu device on whatever adapter the machine has, and the
//!   run-time evaluation of the vertex methods in WGSL.

/// `eprintln!` in one write, stamped with the time (UTC, RFC 3339), for
/// the worker's and the server's logs: `aobake serve`'s local workers
/// share its stderr, and `eprintln!` writes a line in pieces that theirs
/// interleave; the stamp tells when a job ended or a retry began, in a
/// log of many processes.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::say_line(format_args!($($arg)*))
    };
}

/// The time now as [`say!`] stamps a line: UTC, RFC 3339, milliseconds.
pub fn stamp() -> String {
    humantime::format_rfc3339_millis(std::time::SystemTime::now()).to_string()
}

/// What [`say!`] writes: `args` as one stamped line on stderr.
pub fn say_line(args: std::fmt::Arguments<'_>) {
    let line = format!("{} {args}\n", stamp());
    let _ = std::io::Write::write_all(&mut std::io::stderr().lock(), line.as_bytes());
}

pub mod gpu;
pub mod runner;

pub use runner::{RunError, WorkerConfig, run};
