//! `aobake serve`: the API on the embedded defaults (SQLite and blobs
//! under one data directory) with local worker processes it spawns and
//! restarts, a lease reaper, and graceful shutdown.

use aobake_worker::stamp;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use tokio::process::{Child, Command};

use crate::{
    app::app,
    auth::{Scope, new_token, token_hash},
    blobs::{self, Blobs, LocalBlobs},
    error::ApiError,
    listen::{
        Listener,
        tls::{Certificate, TlsFiles},
    },
    state::{AppState, ServerLimits},
    store::{PgStore, QueuePolicy, SqliteStore, Store, StoreError},
};

/// The environment variable that gives `aobake serve` its admin token
/// (else it makes one and writes it to `admin.token`).
pub const ADMIN_TOKEN_ENV: &str = "AOBAKE_ADMIN_TOKEN";

/// The stores a server runs on: `serve`'s, and an operator's command's
/// (`aobake blobs verify`) given the same.
#[derive(Debug, Clone, clap::Args)]
pub struct Backing {
    /// Where the database, the blobs, `server.url` and `admin.token` live.
    #[arg(long, env = "AOBAKE_DATA", default_value = "aobake-data")]
    pub data: PathBuf,
    /// The metadata store: empty for SQLite in --data (the embedded
    /// default), or a PostgreSQL URL (`postgres://user@host:port/db`) for
    /// several servers and remote workers.
    #[arg(long, env = "AOBAKE_DATABASE", value_parser = postgres_url_arg)]
    pub database: Option<String>,
    /// Where blobs (uploads, assets, checkpoints) live: empty for a folder
    /// in --data (the embedded default), a directory, or an S3-compatible
    /// bucket that several servers share,
    /// `s3://BUCKET[/PREFIX]?endpoint=URL&region=R&allow_http=true` (each
    /// query pair any `object_store` S3 setting; the credentials from
    /// AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY).
    #[arg(long, env = "AOBAKE_BLOBS")]
    pub blobs: Option<String>,
}

/// `aobake serve`'s settings.
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
    /// Its stores.
    #[command(flatten)]
    pub backing: Backing,
    /// Address to listen on; port 0 picks a free one.
    #[arg(long, env = "AOBAKE_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Speak https on --listen with this certificate: a PEM file, the
    /// server's own certificate first, then the chain to its CA (with
    /// --tls-key). SIGHUP reads both files again. The commands and local
    /// workers of this machine then use a plain-HTTP listener on
    /// 127.0.0.1 that `server.url` names.
    #[arg(
        long,
        env = "AOBAKE_TLS_CERT",
        requires = "tls_key",
        value_name = "PEM"
    )]
    pub tls_cert: Option<PathBuf>,
    /// The private key of --tls-cert: a PEM file (PKCS#8, PKCS#1 or SEC1,
    /// not encrypted; may be the certificate's own file).
    #[arg(
        long,
        env = "AOBAKE_TLS_KEY",
        requires = "tls_cert",
        value_name = "PEM"
    )]
    pub tls_key: Option<PathBuf>,
    /// Local worker processes to start and supervise (default: one per
    /// core; 0: none, for remote workers only).
    #[arg(long, env = "AOBAKE_WORKERS")]
    pub workers: Option<usize>,
    /// A lease lasts this long unless heartbeated.
    #[arg(long, env = "AOBAKE_LEASE_SECS", default_value_t = 30.0)]
    pub lease_secs: f64,
    /// Leases a job gets before it is dead and its bake failed.
    #[arg(long, env = "AOBAKE_MAX_ATTEMPTS", default_value_t = 5)]
    pub max_attempts: i64,
    /// Largest request body in bytes.
    #[arg(long, env = "AOBAKE_MAX_BODY_BYTES", default_value_t = 256 << 20)]
    pub max_body_bytes: u64,
    /// Most ray-vertex pairs one bake may trace (poses × vertices ×
    /// samples).
    #[arg(long, env = "AOBAKE_MAX_BAKE_WORK", default_value_t = 200_000_000_000)]
    pub max_bake_work: u128,
    /// Most bytes of uploads one bake may use (its character and clip
    /// files together; every import of the bake holds them in memory).
    #[arg(long, env = "AOBAKE_MAX_BAKE_INPUT_BYTES", default_value_t = 1 << 30)]
    pub max_bake_input_bytes: u64,
    /// Requests per second per token.
    #[arg(long, env = "AOBAKE_RATE", default_value_t = 200)]
    pub rate: u32,
    /// A client must send its request headers within this many seconds.
    #[arg(long, env = "AOBAKE_HEADER_TIMEOUT_SECS", default_value_t = 10.0)]
    pub header_timeout_secs: f64,
    /// Rays a tracing job (`sample`, `preview-truth`) aims for: a batch
    /// takes as many poses as make about this many, 4 at least (0: 4 poses
    /// each). Larger jobs cost the queue less per ray; smaller ones lose
    /// less to a lost worker and spread a small bake over more workers.
    #[arg(long, env = "AOBAKE_JOB_RAYS", default_value_t = aobake_core::bake::GraphOptions::default().sample_rays)]
    pub job_rays: u64,
    /// Also upload the bundled Fox, start a fresh bake of it (a new seed
    /// each time, so it is never a cached result), and print a dashboard
    /// URL that signs in with a new read-and-submit token.
    #[arg(long)]
    pub demo: bool,
}

/// Writes `text` to `path`, readable by this user alone, atomically.
fn write_private(path: &Path, text: &str) -> anyhow::Result<()> {
    use std::io::Write as _;
    let dir = path.parent().unwrap_or(Path::new("."));
    let cannot = || format!("cannot write {}", path.display());
    // A temporary file (mode 0600) renamed into place: a reader never
    // sees it empty or half written.
    let mut tmp = tempfile::NamedTempFile::new_in(dir).with_context(cannot)?;
    tmp.write_all(text.as_bytes()).with_context(cannot)?;
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(cannot)?;
    Ok(())
}

/// Workers not seen for this long (a day, in ms) leave `GET /v1/workers`.
const FORGET_WORKERS_MS: i64 = 24 * 3600 * 1000;

/// `--database`: a PostgreSQL URL (the only other store than the
/// embedded SQLite), so another scheme is a wrong command line.
fn postgres_url_arg(s: &str) -> Result<String, String> {
    match s.split_once("://") {
        Some(("postgres" | "postgresql", _)) => Ok(s.to_owned()),
        _ => Err(
            "--database takes a PostgreSQL URL (postgres://USER@HOST:PORT/DB); leave it out for SQLite in --data"
                .to_owned(),
        ),
    }
}

/// Runs the server until SIGTERM or Ctrl-C.
pub async fn serve(args: ServeArgs) -> anyhow::Result<()> {
    // jemalloc (the binary's allocator) purges freed pages on its own
    // threads, so memory a burst of uploads freed goes back to the system
    // while the server idles, not at its next allocation.
    if let Err(e) = tikv_jemalloc_ctl::background_thread::write(true) {
        log_line!("warning: jemalloc's background purging is off: {e}");
    }
    // Files that cannot serve are told before anything else starts.
    let certificate = match (&args.tls_cert, &args.tls_key) {
        (Some(cert), Some(key)) => Some(Certificate::load(TlsFiles {
            cert: cert.clone(),
            key: key.clone(),
        })?),
        _ => None,
    };
    if let Some(why) = certificate
        .as_deref()
        .and_then(Certificate::refused_by_clients)
    {
        log_line!("warning: {why}");
    }
    // SIGHUP is taken from here on: a renewal's hook that sends one while
    // the server still starts must not stop it (the signal's default),
    // and the reload waits until the listeners are up.
    #[cfg(unix)]
    let hangups = match &certificate {
        Some(_) => Some(
            tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())
                .context("cannot handle SIGHUP")?,
        ),
        None => None,
    };
    let (store, blobs) = args.backing.open().await?;
    let policy = QueuePolicy {
        lease_ms: (args.lease_secs * 1000.0) as i64,
        max_attempts: args.max_attempts,
        ..QueuePolicy::default()
    };
    let limits = ServerLimits {
        max_body_bytes: args.max_body_bytes,
        requests_per_second: args.rate,
        max_bake_work: args.max_bake_work,
        max_bake_input_bytes: args.max_bake_input_bytes,
        ..ServerLimits::default()
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let workers = args.workers.unwrap_or(cores);
    let Tokens {
        admin,
        worker: worker_token,
        demo: demo_token,
    } = start_tokens(&*store, &args, workers).await?;
    let mut state = AppState::new(store.clone(), blobs, policy, limits);
    state.graph.sample_rays = args.job_rays;
    store.listen(state.jobs_ready.clone()).await?;
    state.share_events().await?;
    let tcp = tokio::net::TcpListener::bind(args.listen)
        .await
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    // `url` is where this machine's commands and local workers reach the
    // server (`server.url`); `public`, where others do.
    let (url, public, listeners) = match &certificate {
        None => {
            let url = format!("http://{}", tcp.local_addr()?);
            println!("{} listening on {url}", stamp());
            let plain = Listener { tcp, tls: None };
            (url.clone(), url, vec![plain])
        }
        Some(certificate) => {
            // The certificate names the server's public name, not
            // 127.0.0.1, and this machine may not trust its CA: the
            // commands here and the local workers use a listener of
            // their own on the loopback, which nothing off the machine
            // reaches.
            let local = tokio::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
                .await
                .context("cannot listen on 127.0.0.1")?;
            let addr = tcp.local_addr()?;
            let names = certificate.names();
            let public = https_url(addr, &names);
            let url = format!("http://{}", local.local_addr()?);
            println!(
                "{} listening on https://{addr} (TLS, certificate {} for {}) and, for this machine's commands and workers, on {url}",
                stamp(),
                certificate.files().cert.display(),
                if names.is_empty() {
                    "no host".to_owned()
                } else {
                    names.join(", ")
                }
            );
            let tls = Listener {
                tcp,
                tls: Some(certificate.config()?),
            };
            let local = Listener {
                tcp: local,
                tls: None,
            };
            (url, public, vec![tls, local])
        }
    };
    write_private(&args.backing.data.join("server.url"), &url)?;
    if !args.demo {
        println!(
            "{} dashboard: {public}/ (sign in with a token from `aobake token create --scope read`)",
            stamp()
        );
    }
    #[cfg(unix)]
    if let (Some(certificate), Some(hangups)) = (certificate.clone(), hangups) {
        reload_on_hangup(certificate, hangups);
    }

    // Leases that expire without a heartbeat free their jobs.
    let reaper = {
        let state = state.clone();
        // No lease is reaped in the first lease's length after this server
        // starts or its database answers again: workers whose heartbeats
        // could not get through meanwhile (a restart, an outage longer
        // than a lease) renew theirs first, and their jobs keep their
        // attempts.
        let grace = Duration::from_millis(u64::try_from(state.policy.lease_ms).unwrap_or(0));
        tokio::spawn(async move {
            let mut hold_until = Some(tokio::time::Instant::now() + grace);
            let mut forgot = tokio::time::Instant::now();
            loop {
                tokio::time::sleep(Duration::from_millis(500)).await;
                // Once a minute: workers gone for a day leave the list
                // (a default id is host and process id: each start adds
                // one).
                if forgot.elapsed() >= Duration::from_secs(60) {
                    forgot = tokio::time::Instant::now();
                    if let Err(e) = state.store.forget_workers(FORGET_WORKERS_MS).await {
                        log_line!("error: forgetting gone workers: {e}");
                    }
                }
                match hold_until {
                    // The database is down: wait for it to answer.
                    None => {
                        // (The store's connections log when it answers
                        // again: `store::Outages`.)
                        if state.store.ping().await.is_ok() {
                            hold_until = Some(tokio::time::Instant::now() + grace);
                        }
                        continue;
                    }
                    Some(t) if tokio::time::Instant::now() < t => continue,
                    Some(_) => {}
                }
                match state.store.reap().await {
                    Ok(n) if n > 0 => state.jobs_ready.notify_waiters(),
                    Ok(_) => {}
                    Err(e) => {
                        log_line!("error: reaping leases: {e}");
                        hold_until = None;
                    }
                }
            }
        })
    };
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let mut supervisors = Vec::new();
    // Mesa's drivers, which a worker opens to look for a GPU, print
    // "XDG_RUNTIME_DIR is invalid or not set" at every start where the
    // variable is unset (a service, a container): give the local workers
    // a private one under the data folder instead.
    let runtime_dir = match std::env::var_os("XDG_RUNTIME_DIR") {
        // libwayland takes only an absolute path.
        Some(d) if Path::new(&d).is_absolute() => None,
        _ => Some(private_dir(&args.backing.data.join("run"))?),
    };
    for slot in 0..workers {
        // (Made exactly when there are local workers.)
        let Some(token) = worker_token.clone() else {
            break;
        };
        let url = url.clone();
        let runtime_dir = runtime_dir.clone();
        let threads = (cores / workers.max(1)).max(1);
        let mut stop = stop_rx.clone();
        let lease_secs = args.lease_secs;
        supervisors.push(tokio::spawn(async move {
            let mut restarts = 0u32;
            loop {
                let spawned = spawn_worker(&url, &token, slot, threads, lease_secs, runtime_dir.as_deref());
                let mut child = match spawned {
                    Ok(c) => c,
                    Err(e) => {
                        log_line!("error: cannot start worker {slot}: {e:#}");
                        return;
                    }
                };
                // Held, not given to `wait` (which closes a child's stdin
                // first): the worker stops when it closes.
                let _pipe = child.stdin.take();
                tokio::select! {
                    status = child.wait() => {
                        let refused = aobake_worker::RunError::REFUSED_EXIT;
                        if matches!(&status, Ok(s) if s.code() == Some(i32::from(refused))) {
                            log_line!("worker {slot}: the server refuses its token (revoked?); not restarting it");
                            return;
                        }
                        restarts += 1;
                        let wait = Duration::from_millis(250 * u64::from(restarts.min(20)));
                        log_line!("worker {slot} exited ({status:?}); restarting in {wait:?}");
                        tokio::time::sleep(wait).await;
                    }
                    _ = stop.changed() => {
                        terminate(&mut child).await;
                        return;
                    }
                }
            }
        }));
    }
    if let Some(dashboard) = demo_token {
        let (url, public, admin) = (url.clone(), public.clone(), admin.clone());
        tokio::spawn(async move {
            if let Err(e) = crate::demo::run(&url, &public, &admin, &dashboard).await {
                log_line!("error: the demo bake could not be submitted: {e:#}");
            }
        });
    }
    let stopping = state.clone();
    let shutdown = async move {
        let ctrl_c = tokio::signal::ctrl_c();
        #[cfg(unix)]
        {
            let mut term =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                    .expect("SIGTERM handler");
            tokio::select! { _ = ctrl_c => {}, _ = term.recv() => {} }
        }
        #[cfg(not(unix))]
        let _ = ctrl_c.await;
        log_line!("shutting down: ending long polls, stopping local workers");
        // Long polls answer at once; local workers get SIGTERM, finish (or
        // give back) their jobs while the API still serves their
        // completions, and exit; then the API stops.
        stopping.shut_down();
        let _ = stop_tx.send(true);
        for s in supervisors {
            let _ = s.await;
        }
    };
    crate::listen::serve(
        listeners,
        app(state),
        Duration::from_secs_f64(args.header_timeout_secs),
        shutdown,
    )
    .await?;
    reaper.abort();
    Ok(())
}

/// The https address others reach a server listening on `addr` at: the
/// address itself when its certificate names that IP (or names nothing),
/// else the certificate's first name that is not a wildcard, on the port.
fn https_url(addr: SocketAddr, names: &[String]) -> String {
    let ip = addr.ip().to_string();
    if names.contains(&ip) {
        return format!("https://{addr}");
    }
    match names.iter().find(|n| !n.starts_with('*')) {
        Some(name) if name.parse::<std::net::Ipv6Addr>().is_ok() => {
            format!("https://[{name}]:{}", addr.port())
        }
        Some(name) => format!("https://{name}:{}", addr.port()),
        None => format!("https://{addr}"),
    }
}

/// Reads the certificate's files again at every SIGHUP (as nginx does):
/// a renewed certificate is served from the next handshake on, and one
/// that does not load is logged and leaves the previous one served.
#[cfg(unix)]
fn reload_on_hangup(certificate: Arc<Certificate>, mut hangups: tokio::signal::unix::Signal) {
    tokio::spawn(async move {
        while hangups.recv().await.is_some() {
            match certificate.reload() {
                Ok(()) => {
                    log_line!(
                        "reloaded the TLS certificate {}",
                        certificate.files().cert.display()
                    );
                    if let Some(why) = certificate.refused_by_clients() {
                        log_line!("warning: {why}");
                    }
                }
                Err(e) => log_line!(
                    "error: the TLS certificate was not reloaded, the previous one is still served: {e:#}"
                ),
            }
        }
    });
}

/// The secrets a start uses: the admin token, its local workers' and the
/// demo dashboard's (each `None` when not made).
struct Tokens {
    admin: String,
    worker: Option<String>,
    demo: Option<String>,
}

/// Sets up this start's tokens. The tokens the previous start on this data
/// folder generated are deleted first; the admin token comes from
/// `AOBAKE_ADMIN_TOKEN` or is generated into `DIR/admin.token`; local
/// workers (`workers` > 0) and `--demo` get tokens of their own, which the
/// next start deletes in turn (`DIR/own-tokens`).
async fn start_tokens(
    store: &dyn Store,
    args: &ServeArgs,
    workers: usize,
) -> anyhow::Result<Tokens> {
    // The tokens the previous start on this data folder made are revoked:
    // its admin secret (the file now gets a new one) and its local
    // workers' must not stay valid. An admin token from the environment
    // is the operator's to keep; it is never revoked here.
    let own_tokens = args.backing.data.join("own-tokens");
    let previous = std::fs::read_to_string(&own_tokens).unwrap_or_default();
    let previous: Vec<&str> = previous
        .lines()
        .map(str::trim)
        .filter(|h| !h.is_empty())
        .collect();
    let given = std::env::var(ADMIN_TOKEN_ENV)
        .ok()
        .filter(|t| !t.is_empty());
    let given_hash = given.as_deref().map(token_hash);
    // (Not the one the operator now gives, such as an earlier start's
    // generated secret kept: revoking it would keep it off for good.)
    for hash in previous
        .iter()
        .filter(|&&h| Some(h) != given_hash.as_deref())
    {
        store.delete_token(hash, false).await?;
    }
    let mut made = Vec::new();
    // The tokens this start makes are named after it, so that `token
    // list` on a fleet tells whose each is.
    let origin = format!(
        "serve on {}, {}",
        host_name(),
        std::path::absolute(&args.backing.data)
            .unwrap_or_else(|_| args.backing.data.clone())
            .display()
    );
    let admin_file = args.backing.data.join("admin.token");
    let (admin, admin_name) = match given {
        Some(t) => {
            // The file holds a token an earlier start generated, revoked
            // above: clients read it by default, so it goes too.
            // (Unless it is the token the operator now gives.)
            let stale = std::fs::read_to_string(&admin_file).is_ok_and(|old| {
                old.trim() != t && previous.contains(&token_hash(old.trim()).as_str())
            });
            if stale {
                std::fs::remove_file(&admin_file).with_context(|| {
                    format!("cannot remove the revoked {}", admin_file.display())
                })?;
                println!(
                    "{} removed {} (an earlier start's admin token, now revoked; {ADMIN_TOKEN_ENV} is the admin token)",
                    stamp(),
                    admin_file.display()
                );
            }
            // One name on every server that shares it.
            (t, "admin".to_owned())
        }
        None => {
            let t = new_token();
            write_private(&admin_file, &t)?;
            // Its path, not the secret: a log (a CI job's, a service
            // manager's) is read by more people than the token is for.
            println!(
                "{} admin token: generated into {} (the aobake commands here read it; `cat` it to sign in to the dashboard)",
                stamp(),
                admin_file.display()
            );
            made.push(token_hash(&t));
            (t, format!("admin ({origin})"))
        }
    };
    match store
        .create_token(
            &token_hash(&admin),
            &admin_name,
            &[Scope::Admin.name().to_owned()],
        )
        .await
    {
        // A revoked secret stays revoked, on every server of a fleet and
        // across restarts: this start goes on without it (the other
        // tokens, and other admin tokens, still work).
        Err(StoreError::Revoked(_)) => log_line!(
            "warning: {ADMIN_TOKEN_ENV} was revoked (aobake token revoke) and stays revoked: it is refused; set a new secret (aobake token create --scope admin makes one)"
        ),
        other => other?,
    }
    // So does an expired one: a start keeps a secret's expiry.
    if let Some(at) = store
        .token(&token_hash(&admin))
        .await?
        .and_then(|row| row.expired(crate::auth::now_ms()))
    {
        log_line!(
            "warning: {ADMIN_TOKEN_ENV} expired ({}) and stays expired: it is refused; set a new secret (aobake token create --scope admin makes one)",
            ApiError::TokenExpired(at)
        );
    }
    // Only a start with local workers makes them a token: the servers of a
    // fleet, whose workers run elsewhere, leave none in the shared tokens.
    let worker = if workers > 0 {
        let name = format!("local workers ({origin})");
        Some(own_token(store, &mut made, &name, &[Scope::Worker]).await?)
    } else {
        None
    };
    // The demo's dashboard token (read and submit, printed in a URL) is
    // this start's too: the next start revokes it with the others.
    let demo = if args.demo {
        let scopes = [Scope::Read, Scope::Submit];
        let name = format!("demo dashboard ({origin})");
        Some(own_token(store, &mut made, &name, &scopes).await?)
    } else {
        None
    };
    write_private(&own_tokens, &(made.join("\n") + "\n"))?;
    Ok(Tokens {
        admin,
        worker,
        demo,
    })
}

/// This machine's name (`/etc/hostname`), or `localhost`.
pub fn host_name() -> String {
    std::fs::read_to_string("/etc/hostname")
        .map(|h| h.trim().to_owned())
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
}

/// A new token of `scopes` named `name`, stored, its hash added to `made`
/// (this start's own tokens, which the next start revokes).
async fn own_token(
    store: &dyn Store,
    made: &mut Vec<String>,
    name: &str,
    scopes: &[Scope],
) -> anyhow::Result<String> {
    let token = new_token();
    let hash = token_hash(&token);
    let scopes: Vec<String> = scopes.iter().map(|s| s.name().to_owned()).collect();
    store.create_token(&hash, name, &scopes).await?;
    made.push(hash);
    Ok(token)
}

fn spawn_worker(
    url: &str,
    token: &str,
    slot: usize,
    threads: usize,
    lease_secs: f64,
    runtime_dir: Option<&Path>,
) -> anyhow::Result<Child> {
    let exe = std::env::current_exe().context("cannot find the aobake binary")?;
    let id = format!("local-{slot}-{}", std::process::id());
    let mut command = Command::new(exe);
    command
        .args([
            "worker",
            "--server",
            url,
            "--id",
            &id,
            "--stop-at-stdin-end",
        ])
        .arg("--heartbeat-secs")
        .arg((lease_secs / 4.0).to_string())
        .env("AOBAKE_TOKEN", token)
        .env("RAYON_NUM_THREADS", threads.to_string())
        // A pipe this process holds the writing end of: it closes when
        // serve exits however it exits (SIGKILL, a crash), and the worker
        // stops then instead of polling a server that has gone.
        .stdin(std::process::Stdio::piped())
        .kill_on_drop(true);
    if let Some(dir) = runtime_dir {
        command.env("XDG_RUNTIME_DIR", dir);
    }
    command.spawn().context("cannot start a worker process")
}

/// `dir`, created if missing, readable by this user only (as a runtime
/// directory must be).
fn private_dir(dir: &Path) -> anyhow::Result<std::path::PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
            .with_context(|| format!("cannot restrict {}", dir.display()))?;
    }
    Ok(dir.to_path_buf())
}

async fn terminate(child: &mut Child) {
    #[cfg(unix)]
    if let Some(pid) = child.id().and_then(|p| i32::try_from(p).ok()) {
        use nix::sys::signal::{Signal, kill};
        let _ = kill(nix::unistd::Pid::from_raw(pid), Signal::SIGTERM);
        if tokio::time::timeout(Duration::from_secs(30), child.wait())
            .await
            .is_ok()
        {
            return;
        }
    }
    let _ = child.kill().await;
}

impl Backing {
    /// The metadata store and the blob store (what `--data`, `--database`
    /// and `--blobs` name): a bucket that is not there (or refuses these
    /// credentials) is refused here, not at the first upload.
    pub(crate) async fn open(&self) -> anyhow::Result<(Arc<dyn Store>, Arc<dyn Blobs>)> {
        let (data, database, blob_url) =
            (&self.data, self.database.as_deref(), self.blobs.as_deref());
        std::fs::create_dir_all(data)
            .with_context(|| format!("cannot create {}", data.display()))?;
        let store: Arc<dyn Store> = match database {
            Some(url) => Arc::new(
                PgStore::connect(url)
                    .await
                    .context("cannot connect to PostgreSQL")?,
            ),
            None => Arc::new(
                SqliteStore::open(&data.join("aobake.db"))
                    .await
                    .context("cannot open the database")?,
            ),
        };
        let blobs: Arc<dyn Blobs> = blobs::Watched::over(match blob_url {
            Some(url) => blobs::open(url)?,
            None => Arc::new(LocalBlobs::open(&data.join("blobs"))?),
        });
        if let Some(url) = blob_url {
            let shown = blobs::redacted(url);
            match tokio::time::timeout(std::time::Duration::from_secs(15), blobs.probe()).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => anyhow::bail!("the blob store {shown} cannot be used: {e}"),
                Err(_) => anyhow::bail!("the blob store {shown} did not answer in 15 s"),
            }
        }
        Ok((store, blobs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_https_address_is_one_the_certificate_names() {
        let at = |addr: &str, names: &[&str]| {
            let names: Vec<String> = names.iter().map(|&n| n.to_owned()).collect();
            https_url(addr.parse().unwrap(), &names)
        };
        assert_eq!(
            at("127.0.0.1:8443", &["localhost", "127.0.0.1"]),
            "https://127.0.0.1:8443"
        );
        assert_eq!(
            at("0.0.0.0:8443", &["*.studio.lan", "bake.studio.lan"]),
            "https://bake.studio.lan:8443"
        );
        assert_eq!(at("0.0.0.0:8443", &["::1"]), "https://[::1]:8443");
        assert_eq!(at("[::]:8443", &[]), "https://[::]:8443");
    }
}
