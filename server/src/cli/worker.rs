//! `aobake worker`: runs jobs for a server (aobake-worker's lease loop) in
//! this process; many may run on many machines.

/// Arguments of `aobake worker`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Runs until SIGTERM or SIGINT (jobs then finish, or stop at a checkpoint and give their leases back). Exits 3 when the server refuses its leases in a way that waiting does not mend (a token that is not valid or lacks the worker scope, an address that is not an aobake server), saying what to check; `aobake serve` does not restart a local worker that does."
)]
pub(super) struct WorkerArgs {
    /// The server's URL; for a fleet without a load balancer, several,
    /// comma-separated (servers on one database and blob store): when the
    /// one it asks cannot be reached, the worker goes on with the next. An
    /// https:// server's certificate must be one the machine trusts (its
    /// store; SSL_CERT_FILE or SSL_CERT_DIR replace the store).
    #[arg(long, env = "AOBAKE_SERVER", value_parser = super::common::server_list)]
    server: String,
    /// A token with the worker scope.
    #[arg(long, env = "AOBAKE_TOKEN", hide_env_values = true)]
    token: String,
    /// Jobs at once, one thread each: the idle ones are leased jobs in
    /// one request, and jobs that finish together are completed in one.
    #[arg(long, env = "AOBAKE_CONCURRENCY", default_value_t = 1,
        value_parser = clap::value_parser!(u64).range(1..=64))]
    concurrency: u64,
    /// This worker's name (default: host name and process id; at most
    /// 120 characters).
    #[arg(long, value_parser = worker_id)]
    id: Option<String>,
    /// Seconds between heartbeats (well under the server's lease).
    #[arg(long, default_value_t = 5.0)]
    heartbeat_secs: f64,
    /// A job's checkpoints are saved at most this often (seconds of work
    /// since its last saved one): a crash costs at most this much work,
    /// and fast steps (a pose of a small character) do not spend the
    /// server's time on saves. 0 saves every checkpoint a job offers.
    #[arg(long, env = "AOBAKE_CHECKPOINT_SECS", default_value_t = 2.0)]
    checkpoint_secs: f64,
    /// The GPU tracer: `auto` (a hardware GPU with compute shaders when
    /// there is one, else the CPU), `off` (the CPU), or `require` (any
    /// adapter with compute, software ones too; the worker does not start
    /// without one).
    #[arg(long, value_enum, env = "AOBAKE_GPU", default_value = "auto")]
    gpu: GpuChoice,
    /// On SIGTERM, seconds a running job may take to finish before it
    /// stops at its next checkpoint and gives its lease back.
    #[arg(long, default_value_t = 20)]
    shutdown_secs: u64,
    /// Stop as at SIGTERM when standard input reaches its end: `aobake
    /// serve` gives its local workers a pipe, so that they do not outlive
    /// it even when it is killed outright.
    #[arg(long, hide = true)]
    stop_at_stdin_end: bool,
}

/// `--gpu`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum GpuChoice {
    Auto,
    Off,
    Require,
}

/// Runs the lease loop until SIGTERM.
pub(super) fn run(args: &WorkerArgs) -> anyhow::Result<()> {
    use super::common::TracerChoice;
    let tracer = match args.gpu {
        GpuChoice::Auto => TracerChoice::Auto,
        GpuChoice::Off => TracerChoice::Cpu,
        GpuChoice::Require => TracerChoice::Gpu,
    };
    let (server, fallbacks) = super::common::servers(&args.server)?;
    tracer.install(true)?;
    let host = crate::serve::host_name();
    aobake_worker::run(aobake_worker::WorkerConfig {
        server,
        fallbacks,
        token: args.token.clone(),
        concurrency: args.concurrency as usize,
        id: args
            .id
            .clone()
            .unwrap_or_else(|| format!("{host}-{}", std::process::id())),
        wait_secs: 20,
        heartbeat_secs: args.heartbeat_secs,
        checkpoint_secs: args.checkpoint_secs,
        shutdown_secs: args.shutdown_secs,
        stop_at_stdin_end: args.stop_at_stdin_end,
        fault: std::env::var("AOBAKE_FAULT").ok(),
    })
    .map_err(|e| match e {
        // Stamped as every line of a worker's log is.
        aobake_worker::RunError::Refused(message) => super::client::Exit {
            code: aobake_worker::RunError::REFUSED_EXIT,
            message: format!("{} {message}", aobake_worker::stamp()),
        }
        .into(),
        aobake_worker::RunError::Setup(message) => {
            anyhow::Error::msg(format!("{} {message}", aobake_worker::stamp()))
        }
    })
}

/// `--id`: a name the server takes (its slots add `/N`).
fn worker_id(s: &str) -> Result<String, String> {
    if s.is_empty() || s.len() > 120 {
        return Err(format!(
            "a worker id has 1 to 120 characters, not {}",
            s.len()
        ));
    }
    Ok(s.to_owned())
}
