//! `aobake bench queue` and `aobake bench api`: the service's own speed.
//!
//! * `queue`: jobs scheduled per second (lease + complete) on a store,
//!   straight through the store trait with concurrent claimers, and through
//!   HTTP against a real `aobake serve` process with worker threads.
//! * `api`: latency of `GET /v1/bakes/{id}` (p50, p99) under concurrent
//!   pollers, and the server process's memory.

use crate::cli::common::median;
use aobake_api::{BakeRequest, Client, Completion, JobCompletion, NewTokenRequest, OutputRef};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use serde_json::json;

use crate::store::{NewBake, NewJob, PgStore, QueuePolicy, SqliteStore, Store, UploadRow};

/// Arguments of `aobake bench queue`.
#[derive(Debug, clap::Args)]
pub(super) struct QueueArgs {
    /// A PostgreSQL URL to measure instead of SQLite in a temporary
    /// directory.
    #[arg(long)]
    database: Option<String>,
    /// Jobs to schedule.
    #[arg(long, default_value_t = 20_000)]
    jobs: usize,
    /// Concurrent claimers (tasks through the store; threads over HTTP).
    #[arg(long, default_value_t = 8)]
    workers: usize,
    /// Jobs each claimer leases per request and completes per request
    /// (at most 64; 1 is one lease and one completion per job).
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u16).range(1..=64))]
    batch: u16,
    /// Repetitions (medians are printed).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
}

/// Arguments of `aobake bench api`.
#[derive(Debug, clap::Args)]
pub(super) struct ApiArgs {
    /// A PostgreSQL URL for the server instead of SQLite.
    #[arg(long)]
    database: Option<String>,
    /// Concurrent pollers.
    #[arg(long, default_value_t = 200)]
    pollers: usize,
    /// Seconds to poll.
    #[arg(long, default_value_t = 10.0, value_parser = crate::cli::common::positive)]
    secs: f64,
    /// Pause between one poller's requests, in milliseconds (0: as fast
    /// as the server answers).
    #[arg(long, default_value_t = 500)]
    interval_ms: u64,
}

/// The store at `database`, or SQLite at `file`.
pub(super) async fn open_store(
    database: Option<&str>,
    file: &Path,
) -> anyhow::Result<Arc<dyn Store>> {
    Ok(match database {
        Some(url) => Arc::new(PgStore::connect(url).await?),
        None => Arc::new(SqliteStore::open(file).await?),
    })
}

fn new_bake(character: &str, key: String, jobs: usize) -> NewBake {
    NewBake {
        key,
        character: character.into(),
        clips: vec![],
        method: "vertex-linear".into(),
        params: json!({}),
        priority: 0,
        jobs: (0..jobs)
            .map(|i| NewJob {
                kind: "sample".into(),
                spec: json!({"kind": "sample", "set": "reference", "first": 4 * i, "count": 4}),
                work: 4,
                deps: vec![],
            })
            .collect(),
        max_attempts: 5,
    }
}

pub(super) fn queue(args: &QueueArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Runtime::new()?;
    let mut store_rates = Vec::new();
    let mut http_rates = Vec::new();
    for run in 0..args.repeat {
        let dir = tempfile::tempdir()?;
        let rate = rt.block_on(store_queue(args, dir.path(), run))?;
        store_rates.push(rate);
        let dir = tempfile::tempdir()?;
        http_rates.push(http_queue(args, dir.path(), &rt, run)?);
    }
    let backend = if args.database.is_some() {
        "PostgreSQL"
    } else {
        "SQLite"
    };
    println!(
        "{backend}: {} jobs, {} claimers leasing {} at a time, {} runs: through the store {:.0} jobs/s (median; runs {:?}), over HTTP {:.0} jobs/s (median; runs {:?})",
        args.jobs,
        args.workers,
        args.batch,
        args.repeat,
        median(&store_rates),
        store_rates.iter().map(|r| r.round()).collect::<Vec<_>>(),
        median(&http_rates),
        http_rates.iter().map(|r| r.round()).collect::<Vec<_>>(),
    );
    Ok(())
}

/// Queues `jobs` jobs without dependencies in bakes of `per_bake` (whose
/// keys start with `tag`) on `store`.
pub(super) async fn fill_queue(
    store: &dyn Store,
    tag: &str,
    jobs: usize,
    per_bake: usize,
) -> anyhow::Result<Vec<i64>> {
    let character = format!("{:064x}", 0xc0ffee);
    store
        .put_upload(&UploadRow {
            digest: character.clone(),
            kind: "character".into(),
            bundle: false,
            bytes: 0,
            summary: json!({}),
        })
        .await?;
    let mut ids = Vec::new();
    for b in 0..jobs.div_ceil(per_bake) {
        let n = per_bake.min(jobs - b * per_bake);
        let key = format!("{tag}-{b}-{}", std::process::id());
        ids.push(store.create_bake(&new_bake(&character, key, n)).await?.id);
    }
    Ok(ids)
}

/// Lease + complete through the store trait; returns jobs per second.
async fn store_queue(args: &QueueArgs, dir: &Path, run: usize) -> anyhow::Result<f64> {
    let store = open_store(args.database.as_deref(), &dir.join("bench.db")).await?;
    fill_queue(&*store, &format!("store-{run}"), args.jobs, 1000).await?;
    let policy = QueuePolicy::default();
    let started = Instant::now();
    let tasks: Vec<_> = (0..args.workers)
        .map(|w| {
            let store = store.clone();
            let slots = slot_ids(w, args.batch);
            tokio::spawn(async move {
                let mut n = 0usize;
                loop {
                    let leases = store.lease_many(&slots, &policy).await?;
                    if leases.is_empty() {
                        break;
                    }
                    let items: Vec<_> = leases
                        .iter()
                        .map(|l| crate::store::JobCompletion {
                            job: l.job.id,
                            token: l.token.clone(),
                            completion: crate::store::Completion {
                                outputs: vec![],
                                timings: json!({}),
                            },
                        })
                        .collect();
                    for done in store.complete_many(&items).await? {
                        done?;
                        n += 1;
                    }
                }
                anyhow::Ok(n)
            })
        })
        .collect();
    let mut total = 0;
    for t in tasks {
        total += t.await??;
    }
    let secs = started.elapsed().as_secs_f64();
    if total < args.jobs {
        bail!("only {total} of {} jobs were scheduled", args.jobs);
    }
    Ok(total as f64 / secs)
}

/// Claimer `w`'s slots: as a worker process with `batch` threads names
/// them.
fn slot_ids(w: usize, batch: u16) -> Vec<String> {
    (0..batch).map(|s| format!("bench-{w}/{s}")).collect()
}

/// Completions of `leases`, each naming the stored `blob` as its output.
pub(super) fn completions(leases: &[aobake_api::Lease], blob: &str) -> Vec<JobCompletion> {
    leases
        .iter()
        .map(|l| JobCompletion {
            job: l.job.id,
            token: l.token.clone(),
            completion: Completion {
                outputs: vec![OutputRef {
                    name: "ao-reference".into(),
                    digest: blob.to_owned(),
                }],
                timings: json!({}),
            },
        })
        .collect()
}

/// A real `aobake serve` on a free port, killed on drop.
pub(super) struct Server {
    child: Child,
    pub(super) url: String,
    token: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Server {
    fn start(dir: &Path, database: Option<&str>) -> anyhow::Result<Self> {
        Self::start_with(dir, database, None)
    }

    /// Starts one on `dir`, on `database` (SQLite in `dir` without), with
    /// its blobs in `blobs` (`dir`'s own without).
    pub(super) fn start_with(
        dir: &Path,
        database: Option<&str>,
        blobs: Option<&Path>,
    ) -> anyhow::Result<Self> {
        let token = crate::auth::new_token();
        let mut cmd = Command::new(std::env::current_exe()?);
        cmd.args(["serve", "--listen", "127.0.0.1:0", "--workers", "0"])
            .args(["--rate", "1000000"])
            .arg("--data")
            .arg(dir)
            .env("AOBAKE_ADMIN_TOKEN", &token)
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        if let Some(url) = database {
            cmd.args(["--database", url]);
        }
        if let Some(blobs) = blobs {
            cmd.arg("--blobs").arg(blobs);
        }
        let child = cmd.spawn().context("cannot start aobake serve")?;
        let started = Instant::now();
        let url = loop {
            if let Ok(u) = std::fs::read_to_string(dir.join("server.url")) {
                break u.trim().to_owned();
            }
            if started.elapsed() > Duration::from_secs(30) {
                bail!("the server did not start");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        Ok(Self { child, url, token })
    }

    /// Resident and peak memory of the server process, in MiB.
    pub(super) fn memory_mib(&self) -> (f64, f64) {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .unwrap_or_default();
        let field = |name: &str| {
            status
                .lines()
                .find(|l| l.starts_with(name))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<f64>().ok())
                .map_or(f64::NAN, |kb| kb / 1024.0)
        };
        (field("VmRSS:"), field("VmHWM:"))
    }

    pub(super) fn api(&self) -> Client {
        Client::new(&self.url, &self.token)
    }
}

/// Submits a real bake of the bundled RiggedSimple with enough poses for
/// `jobs` sample jobs; returns its id.
fn big_bake(api: &Client, jobs: usize) -> anyhow::Result<i64> {
    static RIGGED: &[u8] =
        include_bytes!("../../../../tests/data/characters/RiggedSimple/RiggedSimple.glb");
    let c = api.upload_character(RIGGED, false, "RiggedSimple.glb")?;
    let params = serde_json::Map::from_iter(
        [
            ("poses", json!(4 * jobs)),
            ("samples", json!(1)),
            ("eval_poses", json!(0)),
            ("seed", json!(rand_seed())),
        ]
        .map(|(k, v)| (k.to_owned(), v)),
    );
    let b = api.submit(&BakeRequest::new(c.digest, "vertex-linear", params))?;
    Ok(b.bake.id)
}

fn rand_seed() -> u64 {
    use rand::RngExt as _;
    rand::rng().random()
}

/// Lease + complete over HTTP with worker threads; returns jobs per
/// second.
fn http_queue(
    args: &QueueArgs,
    dir: &Path,
    rt: &tokio::runtime::Runtime,
    run: usize,
) -> anyhow::Result<f64> {
    // The jobs are queued straight into the server's store before it
    // starts, so the server schedules exactly `jobs` of them.
    rt.block_on(async {
        let store = open_store(args.database.as_deref(), &dir.join("aobake.db")).await?;
        fill_queue(&*store, &format!("http-{run}"), args.jobs, 1000).await
    })?;
    let server = Server::start(dir, args.database.as_deref())?;
    let api = server.api();
    let worker_token = api
        .create_token(&NewTokenRequest {
            name: "bench".to_owned(),
            scopes: vec!["worker".to_owned()],
            expires_in_secs: None,
        })?
        .token;
    let blob = Client::new(&server.url, &worker_token).put_blob(b"x")?;
    let started = Instant::now();
    let counts: Vec<usize> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..args.workers)
            .map(|w| {
                let (url, token, blob) = (&server.url, &worker_token, &blob);
                s.spawn(move || {
                    let client = Client::new(url, token);
                    let slots = slot_ids(w, args.batch);
                    let mut n = 0;
                    while let Ok(leases) = client.lease_many(&slots, 0, None, None) {
                        if leases.is_empty() {
                            break;
                        }
                        let Ok(done) = client.complete_many(&completions(&leases, blob)) else {
                            break;
                        };
                        n += done.iter().filter(|d| d.is_ok()).count();
                    }
                    n
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap_or(0)).collect()
    });
    let secs = started.elapsed().as_secs_f64();
    let total: usize = counts.iter().sum();
    if total < args.jobs {
        bail!("only {total} of {} jobs were scheduled", args.jobs);
    }
    Ok(total as f64 / secs)
}

pub(super) fn api(args: &ApiArgs) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let server = Server::start(dir.path(), args.database.as_deref())?;
    let api = server.api();
    let id = big_bake(&api, 64)?;
    let (rss_idle, _) = server.memory_mib();
    let deadline = Instant::now() + Duration::from_secs_f64(args.secs);
    let path = format!("{}/v1/bakes/{id}", server.url);
    let auth = format!("Bearer {}", server.token);
    let mut latencies: Vec<f64> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..args.pollers)
            .map(|_| {
                let (path, auth) = (&path, &auth);
                s.spawn(move || {
                    let agent: ureq::Agent = ureq::Agent::config_builder()
                        .timeout_global(Some(Duration::from_secs(30)))
                        .build()
                        .into();
                    let mut out = Vec::new();
                    // Pollers start spread over one interval, as clients
                    // that started at different times do.
                    if args.interval_ms > 0 {
                        use rand::RngExt as _;
                        let offset = rand::rng().random_range(0..args.interval_ms);
                        std::thread::sleep(Duration::from_millis(offset));
                    }
                    while Instant::now() < deadline {
                        let t = Instant::now();
                        let ok = agent
                            .get(path)
                            .header("authorization", auth)
                            .call()
                            .and_then(|mut r| r.body_mut().read_to_vec())
                            .is_ok();
                        if ok {
                            out.push(t.elapsed().as_secs_f64() * 1000.0);
                        }
                        std::thread::sleep(Duration::from_millis(args.interval_ms));
                    }
                    out
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    let (rss, peak) = server.memory_mib();
    if latencies.is_empty() {
        bail!("no request succeeded");
    }
    latencies.sort_by(f64::total_cmp);
    let q = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize];
    println!(
        "{} pollers every {} ms for {:.0} s ({}): {} requests ({:.0}/s), latency p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; server memory {:.1} MiB idle, {:.1} MiB under load, peak {:.1} MiB",
        args.pollers,
        args.interval_ms,
        args.secs,
        if args.database.is_some() {
            "PostgreSQL"
        } else {
            "SQLite"
        },
        latencies.len(),
        latencies.len() as f64 / args.secs,
        q(0.5),
        q(0.99),
        latencies[latencies.len() - 1],
        rss_idle,
        rss,
        peak
    );
    Ok(())
}
