//! `aobake bench load`: the service under a studio's load for a bounded
//! time, on loopback: pollers asking for bakes' status, dashboards
//! listening to server-sent events, a build system uploading characters,
//! and a worker completing jobs at a steady rate so the events flow. One
//! server, or two on one PostgreSQL and one blob directory. It prints
//! every interval's requests, 5xx answers, other failures, p99 latency and
//! each server's memory, then the whole run's figures; it stops by itself.

use std::io::BufRead as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::bail;
use aobake_api::{Client, NewTokenRequest};
use serde_json::json;

use super::service::{Server, completions, fill_queue, open_store};
use crate::cli::common::positive;

/// Arguments of `aobake bench load`.
#[derive(Debug, clap::Args)]
pub(super) struct LoadArgs {
    /// API servers: 1, or 2 on one PostgreSQL (`--database`) and one blob
    /// directory.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    servers: u8,
    /// A PostgreSQL URL (required for two servers; SQLite in a temporary
    /// directory otherwise).
    #[arg(long)]
    database: Option<String>,
    /// Seconds of load.
    #[arg(long, default_value_t = 300.0, value_parser = positive)]
    secs: f64,
    /// Clients polling a bake's status (a thread each).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(0..=20_000))]
    pollers: u32,
    /// Milliseconds between one poller's requests.
    #[arg(long, default_value_t = 1000)]
    poll_ms: u64,
    /// Clients listening to `GET /v1/events` (a thread each).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(0..=20_000))]
    sse: u32,
    /// Milliseconds between character uploads (each a new glTF).
    #[arg(long, default_value_t = 1000)]
    upload_ms: u64,
    /// Jobs completed per second (through the first server).
    #[arg(long, default_value_t = 20.0, value_parser = positive)]
    jobs_per_sec: f64,
    /// Seconds per printed interval.
    #[arg(long, default_value_t = 10.0, value_parser = positive)]
    every: f64,
}

/// Counts shared by the clients; an interval's are taken and reset.
#[derive(Debug, Default)]
struct Tally {
    requests: AtomicU64,
    server_errors: AtomicU64,
    /// Connection failures and unexpected 4xx.
    other_errors: AtomicU64,
    events: AtomicU64,
    uploads: AtomicU64,
    jobs: AtomicU64,
    /// Status-request latencies (ms) of the interval.
    latencies: Mutex<Vec<f64>>,
}

impl Tally {
    fn answer(&self, status: Result<u16, ()>, ok: &[u16]) {
        self.requests.fetch_add(1, Ordering::Relaxed);
        match status {
            Ok(s) if ok.contains(&s) => {}
            Ok(s) if s >= 500 => {
                self.server_errors.fetch_add(1, Ordering::Relaxed);
            }
            _ => {
                self.other_errors.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

fn p(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

pub(super) fn load(args: &LoadArgs) -> anyhow::Result<()> {
    if args.servers == 2 && args.database.is_none() {
        bail!("two servers share one PostgreSQL: pass --database postgres://…");
    }
    let dir = tempfile::tempdir()?;
    let blobs = dir.path().join("blobs");
    // The bakes the pollers read and the worker completes: queued in the
    // store before the servers start, 100 jobs each, as many as the run
    // completes.
    let jobs = (args.jobs_per_sec * args.secs).ceil() + 100.0;
    if jobs > 1e7 {
        bail!("--jobs-per-sec × --secs asks for {jobs:.0} jobs; at most 10 million are queued");
    }
    let jobs = jobs as usize;
    let rt = tokio::runtime::Runtime::new()?;
    let data = |i: usize| dir.path().join(format!("server-{i}"));
    let bakes = rt.block_on(async {
        std::fs::create_dir_all(data(0))?;
        let store = open_store(args.database.as_deref(), &data(0).join("aobake.db")).await?;
        fill_queue(&*store, &format!("load-{}", std::process::id()), jobs, 100).await
    })?;
    let servers: Vec<Server> = (0..usize::from(args.servers))
        .map(|i| {
            std::fs::create_dir_all(data(i))?;
            Server::start_with(&data(i), args.database.as_deref(), Some(&blobs))
        })
        .collect::<anyhow::Result<_>>()?;
    let admin = servers[0].api();
    let token = |scope: &str| -> anyhow::Result<String> {
        Ok(admin
            .create_token(&NewTokenRequest {
                name: format!("load-{scope}"),
                scopes: vec![scope.to_owned()],
                expires_in_secs: None,
            })?
            .token)
    };
    let (read, submit, worker) = (token("read")?, token("submit")?, token("worker")?);
    let urls: Vec<String> = servers.iter().map(|s| s.url.clone()).collect();
    let tally = Tally::default();
    let stop = AtomicBool::new(false);
    let deadline = Instant::now() + Duration::from_secs_f64(args.secs);
    println!(
        "{} server(s) on {}: {} pollers every {} ms, {} SSE clients, an upload every {} ms, {} jobs/s, for {:.0} s",
        args.servers,
        if args.database.is_some() {
            "PostgreSQL"
        } else {
            "SQLite"
        },
        args.pollers,
        args.poll_ms,
        args.sse,
        args.upload_ms,
        args.jobs_per_sec,
        args.secs
    );
    let mut memory: Vec<Vec<f64>> = vec![Vec::new(); servers.len()];
    let mut all_latencies: Vec<f64> = Vec::new();
    let (mut requests, mut server_errors, mut other_errors) = (0, 0, 0);
    let (mut events, mut uploads, mut jobs_done) = (0, 0, 0);
    let disconnects = AtomicU64::new(0);
    std::thread::scope(|s| {
        for i in 0..args.pollers as usize {
            let (url, read, bakes, tally) = (&urls[i % urls.len()], &read, &bakes, &tally);
            s.spawn(move || poll(url, read, bakes, args.poll_ms, deadline, tally));
        }
        for i in 0..args.sse as usize {
            let (url, read, tally, disconnects) =
                (&urls[i % urls.len()], &read, &tally, &disconnects);
            s.spawn(move || listen(url, read, deadline, tally, disconnects));
        }
        {
            let (url, submit, tally) = (&urls[0], &submit, &tally);
            s.spawn(move || upload(url, submit, args.upload_ms, deadline, tally));
        }
        {
            let (url, worker, tally, stop) = (&urls[0], &worker, &tally, &stop);
            s.spawn(move || work(url, worker, args.jobs_per_sec, deadline, tally, stop));
        }
        // The reporter: this thread.
        let started = Instant::now();
        let every = Duration::from_secs_f64(args.every);
        println!(
            "{:>6}  {:>8}  {:>4}  {:>5}  {:>8}  {:>8}  {:>6}  {:>4}  {:>5}  memory (MiB)",
            "t (s)", "requests", "5xx", "other", "p50 ms", "p99 ms", "events", "ups", "jobs"
        );
        while Instant::now() < deadline {
            std::thread::sleep(every.min(deadline.saturating_duration_since(Instant::now())));
            let take = |c: &AtomicU64| c.swap(0, Ordering::Relaxed);
            let (r, e5, eo) = (
                take(&tally.requests),
                take(&tally.server_errors),
                take(&tally.other_errors),
            );
            let (ev, up, jb) = (take(&tally.events), take(&tally.uploads), take(&tally.jobs));
            let mut lat = std::mem::take(&mut *tally.latencies.lock().expect("latencies"));
            lat.sort_by(f64::total_cmp);
            let rss: Vec<f64> = servers.iter().map(|s| s.memory_mib().0).collect();
            for (m, r) in memory.iter_mut().zip(&rss) {
                m.push(*r);
            }
            println!(
                "{:>6.0}  {r:>8}  {e5:>4}  {eo:>5}  {:>8.1}  {:>8.1}  {ev:>6}  {up:>4}  {jb:>5}  {}",
                started.elapsed().as_secs_f64(),
                p(&lat, 0.5),
                p(&lat, 0.99),
                rss.iter()
                    .map(|m| format!("{m:.1}"))
                    .collect::<Vec<_>>()
                    .join(" / ")
            );
            requests += r;
            server_errors += e5;
            other_errors += eo;
            events += ev;
            uploads += up;
            jobs_done += jb;
            all_latencies.extend(lat);
        }
        stop.store(true, Ordering::Relaxed);
    });
    all_latencies.sort_by(f64::total_cmp);
    let growth: Vec<String> = memory
        .iter()
        .map(|m| {
            // The median of the run's last third over its first third's,
            // after the first interval (start-up).
            let third = (m.len().saturating_sub(1) / 3).max(1);
            let mid = |xs: &[f64]| {
                let mut v = xs.to_vec();
                v.sort_by(f64::total_cmp);
                v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
            };
            let first = mid(&m[1.min(m.len())..(1 + third).min(m.len())]);
            let last = mid(&m[m.len().saturating_sub(third)..]);
            format!("{first:.1} → {last:.1} MiB ({:+.1})", last - first)
        })
        .collect();
    println!(
        "total: {requests} requests, {server_errors} answered 5xx, {other_errors} other failures, {} SSE streams cut short; status latency p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {events} events heard, {uploads} uploads, {jobs_done} jobs completed; memory (median of the first third → last third): {}",
        disconnects.load(Ordering::Relaxed),
        p(&all_latencies, 0.5),
        p(&all_latencies, 0.99),
        all_latencies.last().copied().unwrap_or(f64::NAN),
        growth.join("; ")
    );
    Ok(())
}

/// Asks for a bake's status every `every_ms`, cycling through `bakes`.
fn poll(url: &str, token: &str, bakes: &[i64], every_ms: u64, deadline: Instant, tally: &Tally) {
    use rand::RngExt as _;
    let agent = aobake_api::client::agent(Duration::from_secs(30));
    let auth = format!("Bearer {token}");
    let mut rng = rand::rng();
    // Clients that started at different times.
    std::thread::sleep(Duration::from_millis(rng.random_range(0..every_ms.max(1))));
    while Instant::now() < deadline {
        let id = bakes[rng.random_range(0..bakes.len())];
        let t = Instant::now();
        let status = agent
            .get(format!("{url}/v1/bakes/{id}"))
            .header("authorization", &auth)
            .call()
            .and_then(|mut r| {
                r.body_mut().read_to_vec()?;
                Ok(r.status().as_u16())
            })
            .map_err(|_| ());
        tally
            .latencies
            .lock()
            .expect("latencies")
            .push(t.elapsed().as_secs_f64() * 1000.0);
        tally.answer(status, &[200]);
        std::thread::sleep(Duration::from_millis(every_ms));
    }
}

/// Listens to `GET /v1/events` until the deadline, counting events; a
/// stream that ends sooner is reconnected and counted as cut short.
fn listen(url: &str, token: &str, deadline: Instant, tally: &Tally, cut: &AtomicU64) {
    while Instant::now() < deadline {
        let left = deadline.saturating_duration_since(Instant::now());
        let res = aobake_api::client::agent(left)
            .get(format!("{url}/v1/events"))
            .header("authorization", format!("Bearer {token}"))
            .call();
        let mut res = match res {
            Ok(r) => r,
            Err(_) => {
                tally.answer(Err(()), &[]);
                std::thread::sleep(Duration::from_millis(500));
                continue;
            }
        };
        tally.answer(Ok(res.status().as_u16()), &[200]);
        if res.status() != 200 {
            std::thread::sleep(Duration::from_millis(500));
            continue;
        }
        let reader = std::io::BufReader::new(res.body_mut().as_reader());
        for line in reader.lines() {
            match line {
                Ok(l) if l.starts_with("event: bake") => {
                    tally.events.fetch_add(1, Ordering::Relaxed);
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
        // The global timeout ends a stream at the deadline; before it,
        // the server cut it.
        if Instant::now() + Duration::from_millis(100) < deadline {
            cut.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The bundled RiggedSimple with `asset.generator` set to `tag`: a new
/// valid `.glb`, so a new upload each time.
fn variant(tag: &str) -> anyhow::Result<Vec<u8>> {
    static RIGGED: &[u8] =
        include_bytes!("../../../../tests/data/characters/RiggedSimple/RiggedSimple.glb");
    let json_len = u32::from_le_bytes(RIGGED[12..16].try_into()?) as usize;
    let mut doc: serde_json::Value = serde_json::from_slice(&RIGGED[20..20 + json_len])?;
    doc["asset"]["generator"] = json!(tag);
    let mut text = serde_json::to_vec(&doc)?;
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let rest = &RIGGED[20 + json_len..];
    let total = 12 + 8 + text.len() + rest.len();
    let mut glb = Vec::with_capacity(total);
    glb.extend_from_slice(&RIGGED[..8]);
    glb.extend_from_slice(&u32::try_from(total)?.to_le_bytes());
    glb.extend_from_slice(&u32::try_from(text.len())?.to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&text);
    glb.extend_from_slice(rest);
    Ok(glb)
}

/// Uploads a new character every `every_ms`.
fn upload(url: &str, token: &str, every_ms: u64, deadline: Instant, tally: &Tally) {
    let agent = aobake_api::client::agent(Duration::from_secs(60));
    let mut n = 0u64;
    while Instant::now() < deadline {
        n += 1;
        let status = variant(&format!("aobake bench load {n} {}", std::process::id()))
            .map_err(|_| ())
            .and_then(|glb| {
                agent
                    .post(format!("{url}/v1/characters?name=load-{n}.glb"))
                    .header("authorization", format!("Bearer {token}"))
                    .header("content-type", "model/gltf-binary")
                    .send(&glb)
                    .and_then(|mut r| {
                        r.body_mut().read_to_vec()?;
                        Ok(r.status().as_u16())
                    })
                    .map_err(|_| ())
            });
        if status == Ok(201) {
            tally.uploads.fetch_add(1, Ordering::Relaxed);
        }
        tally.answer(status, &[201]);
        std::thread::sleep(Duration::from_millis(every_ms));
    }
}

/// Completes queued jobs at `per_sec` through the worker protocol, in
/// batches of what is due.
fn work(url: &str, token: &str, per_sec: f64, deadline: Instant, tally: &Tally, stop: &AtomicBool) {
    let client = Client::new(url, token);
    let blob = match client.put_blob(b"load") {
        Ok(d) => d,
        Err(_) => {
            tally.answer(Err(()), &[]);
            return;
        }
    };
    let started = Instant::now();
    let mut done = 0u64;
    while Instant::now() < deadline && !stop.load(Ordering::Relaxed) {
        let due = (started.elapsed().as_secs_f64() * per_sec) as u64;
        let n = due.saturating_sub(done).min(64) as usize;
        if n == 0 {
            std::thread::sleep(Duration::from_millis(10));
            continue;
        }
        let slots: Vec<String> = (0..n).map(|i| format!("load/{i}")).collect();
        let leases = client.lease_many(&slots, 0, None, None);
        tally.answer(leases.as_ref().map(|_| 200).map_err(|_| ()), &[200]);
        let Ok(leases) = leases else { continue };
        if leases.is_empty() {
            break;
        }
        let answers = client.complete_many(&completions(&leases, &blob));
        tally.answer(answers.as_ref().map(|_| 200).map_err(|_| ()), &[200]);
        let ok = answers.map_or(0, |a| a.iter().filter(|r| r.is_ok()).count()) as u64;
        tally.jobs.fetch_add(ok, Ordering::Relaxed);
        done += ok;
    }
}
