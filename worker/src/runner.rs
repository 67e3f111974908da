//! The lease loop (DESIGN §8): lease, run, heartbeat, checkpoint, complete.

use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use aobake_core::{
    Limits,
    bake::{
        Bake, BakeInputs, BakeParams, Checkpoint, JobError, JobOutput, JobSink, JobSpec, Output,
        Stop, UploadBytes,
    },
};

use aobake_api::{
    ApiError, BakeState, CheckpointRef, Client, Completion, JobCompletion, Lease, OutputRef,
};

/// How soon a moved progress is sent, at most (see the heartbeat loop).
const PROGRESS_EVERY: Duration = Duration::from_secs(1);

/// How a worker runs.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// The server's base URL.
    pub server: String,
    /// Other servers of the same fleet, asked in turn when the one asked
    /// cannot be reached.
    pub fallbacks: Vec<String>,
    /// A token with the `worker` scope.
    pub token: String,
    /// Jobs run at once (one thread each).
    pub concurrency: usize,
    /// This worker's id (host and process id by default).
    pub id: String,
    /// Seconds a lease request waits on the server for a job.
    pub wait_secs: u64,
    /// Seconds between heartbeats.
    pub heartbeat_secs: f64,
    /// Seconds of work between saved checkpoints: a checkpoint offered
    /// sooner after the last saved one (or the job's start) is skipped,
    /// so a crash costs at most this much work. 0 saves every one.
    pub checkpoint_secs: f64,
    /// On SIGTERM, a running job may take this long to finish before it is
    /// stopped at its next checkpoint and its lease given back.
    pub shutdown_secs: u64,
    /// Stop as at SIGTERM when standard input reaches its end (the pipe
    /// `aobake serve` gives its local workers closes when it exits, even
    /// when killed outright).
    pub stop_at_stdin_end: bool,
    /// A fault to inject, for crash tests (`AOBAKE_FAULT`):
    /// `after_checkpoint` aborts the process right after a checkpoint is
    /// saved; `slow` waits 300 ms at each checkpoint step (a long job).
    pub fault: Option<String>,
}

/// Imported inputs of recent bakes, by bake id.
type InputCache = Mutex<HashMap<i64, Arc<BakeInputs>>>;

/// The most completions one request carries (the server's limit).
const MAX_BATCH: usize = 64;

/// A finished job's completion on its way to the server, and where its
/// slot hears the answer.
struct Finished {
    item: JobCompletion,
    answer: mpsc::Sender<Result<(), String>>,
}

/// Runs until SIGTERM (or SIGINT): `concurrency` slots, one thread each,
/// run jobs that one dispatcher leases for all idle slots in one request,
/// and finished jobs are completed together in one request while another
/// is on its way (group commit), so scheduling costs a request per batch,
/// not two per job.
pub fn run(config: WorkerConfig) -> Result<(), RunError> {
    let shutdown = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(signal, shutdown.clone())
            .map_err(|e| RunError::Setup(format!("cannot handle signals: {e}")))?;
    }
    if config.stop_at_stdin_end {
        let (shutdown, id) = (shutdown.clone(), config.id.clone());
        std::thread::spawn(move || {
            // Nothing is written to the pipe: it only ends.
            let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
            if !shutdown.swap(true, Ordering::Relaxed) {
                say!("worker {id}: the process that started it has gone; stopping");
            }
        });
    }
    let client = Client::with_timeout(&config.server, &config.token, Duration::from_secs(120))
        .with_fallbacks(&config.fallbacks)
        .with_notice(|line| say!("{line}"));
    let cache: Arc<InputCache> = Arc::default();
    let slots = config.concurrency.max(1);
    // Each slot is a worker of its own to the server: one job at a time.
    let ids: Vec<String> = (0..slots)
        .map(|slot| {
            if slots > 1 {
                format!("{}/{slot}", config.id)
            } else {
                config.id.clone()
            }
        })
        .collect();
    let (free_tx, free_rx) = mpsc::channel::<usize>();
    let (done_tx, done_rx) = mpsc::channel::<Finished>();
    let poller = Poller::start(client.clone(), config.wait_secs);
    let dispatched = std::thread::scope(|scope| {
        let client = &client;
        let patience = Patience::new(&shutdown, &config);
        scope.spawn(move || complete_batches(client, patience, &done_rx));
        let mut to_slots = Vec::with_capacity(slots);
        for slot in 0..slots {
            let (tx, rx) = mpsc::channel::<Lease>();
            to_slots.push(tx);
            let (free, done) = (free_tx.clone(), done_tx.clone());
            let (config, shutdown, cache) = (&config, &shutdown, &cache);
            scope.spawn(move || {
                for lease in rx {
                    run_leased(client, config, lease, shutdown, cache, &done);
                    let _ = free.send(slot);
                }
            });
        }
        // The slots hold the completer's senders now: it ends after them.
        drop(done_tx);
        let dispatched = dispatch(
            client, &poller, &config, &ids, &shutdown, &free_rx, &to_slots,
        );
        // No more leases are taken: an open poll's answer is given back as
        // soon as it comes, not held while busy slots finish their jobs
        // (with concurrency above 1 that can outlast its lease).
        poller.finish();
        // Slots finish their jobs (or stop them at shutdown's deadline),
        // then end.
        drop(to_slots);
        dispatched
    });
    dispatched?;
    // One quick try: a worker on its way out does not wait for a server
    // that is away (it is then listed as stopped a lease after it was last
    // seen, as a killed one is).
    let quick = client
        .timed(Duration::from_secs(3))
        .with_rate_wait(Duration::ZERO);
    if let Err(e) = quick.workers_stopped(&ids) {
        say!(
            "worker {}: could not tell the server it stopped ({e}); it is listed as stopped once its lease's length has passed",
            config.id
        );
    }
    say!("worker {}: stopped", config.id);
    Ok(())
}

/// Why a worker stopped other than at SIGTERM.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// It could not start.
    #[error("{0}")]
    Setup(String),
    /// The server refused its leases in a way that waiting does not
    /// mend (`aobake worker` exits with [`RunError::REFUSED_EXIT`], and
    /// `aobake serve` does not restart a local worker that does).
    #[error("{0}")]
    Refused(String),
}

impl RunError {
    /// The exit code of a worker whose leases are refused for good.
    pub const REFUSED_EXIT: u8 = 3;
}

/// What to check when the server refuses a lease in a way that waiting
/// does not mend; `None` for a refusal worth retrying. `answered`: a lease
/// request has had the server's answer before.
fn refused_for_good(e: &ApiError, answered: bool) -> Option<&'static str> {
    // A success whose body is not a lease list, before any that was: a
    // web server or a proxy's page that answers every path. Once the
    // server has answered, such a body (a proxy's page in a restart) is
    // worth waiting out.
    if let ApiError::Decode { .. } = e
        && !answered
    {
        return Some(
            "--server answered, but not as an aobake server does: is it the address of another service?",
        );
    }
    Some(match e.status()? {
        401 => "the token is not valid on this server (revoked, or never created here)",
        403 => "the token lacks the worker scope",
        404 | 405 | 501 => "--server is not the address of an aobake server",
        400 => "the server refused the request as it was sent (--concurrency, --id)",
        _ => return None,
    })
}

/// An empty lease answer sooner than this (or than half of `wait_secs`,
/// which a worker that does not long-poll sets to 0) is early: the server
/// did not hold the poll (it holds one for up to `wait_secs`, 20 s).
const EARLY_EMPTY: Duration = Duration::from_secs(1);
/// Early empty answers in a row before the worker says so.
const EARLY_TOLD: u32 = 5;
/// The longest pause before asking again after early empty answers.
const MAX_EARLY_PAUSE: Duration = Duration::from_secs(10);

/// The pause after the `n`th early empty answer in a row: 0.25 s,
/// doubling, up to [`MAX_EARLY_PAUSE`].
fn early_pause(n: u32) -> Duration {
    (Duration::from_millis(250) * 2u32.pow(n.saturating_sub(1).min(6))).min(MAX_EARLY_PAUSE)
}

/// Sleeps `wait`, or less when `shutdown` comes first.
fn pause(wait: Duration, shutdown: &AtomicBool) {
    let until = Instant::now() + wait;
    while Instant::now() < until && !shutdown.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Leases jobs for the idle slots, one request for all of them, until
/// shutdown.
fn dispatch(
    client: &Client,
    poller: &Poller,
    config: &WorkerConfig,
    ids: &[String],
    shutdown: &AtomicBool,
    freed: &mpsc::Receiver<usize>,
    slots: &[mpsc::Sender<Lease>],
) -> Result<(), RunError> {
    let mut failures = 0u32;
    // The process's tracer (installed by `aobake worker --gpu`), told to
    // the server until a request has gone through.
    let tracer = aobake_core::trace::engine::tracer_label();
    let mut told = false;
    let mut idle: BTreeSet<usize> = (0..ids.len()).collect();
    // Sent again unchanged until an answer arrives: a request whose answer
    // was lost gets what it leased (`LeaseManyRequest::request`).
    let mut nonce = next_nonce();
    // Empty answers in a row that came at once, and how soon is at once.
    let mut early = 0u32;
    let early_empty = EARLY_EMPTY.min(Duration::from_secs(config.wait_secs) / 2);
    while !shutdown.load(Ordering::Relaxed) {
        if idle.is_empty() {
            // Every slot is busy: wait for one, looking at shutdown.
            match freed.recv_timeout(Duration::from_millis(200)) {
                Ok(slot) => {
                    idle.insert(slot);
                }
                Err(mpsc::RecvTimeoutError::Timeout) => continue,
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
        }
        idle.extend(freed.try_iter());
        let asked: Vec<String> = idle.iter().map(|&s| ids[s].clone()).collect();
        let polled = Instant::now();
        let leased = match poller.lease(asked, (!told).then(|| tracer.clone()), &nonce, shutdown)? {
            Polled::Answer(answer) => answer,
            // Shutdown during the long poll: stop waiting for it.
            Polled::Stopping => break,
        };
        told |= leased.is_ok();
        match leased {
            Ok(leases) => {
                failures = 0;
                nonce = next_nonce();
                // No job, long before the poll's end: a server ending its
                // polls as it shuts down, or one that does not hold them.
                // Ask again after a pause, not at once.
                if leases.is_empty() && polled.elapsed() < early_empty {
                    early += 1;
                    if early == EARLY_TOLD {
                        say!(
                            "worker {}: the server at {} answers every lease request at once with no job (shutting down, or not holding long polls); asking every {:?} or less",
                            config.id,
                            client.base(),
                            MAX_EARLY_PAUSE
                        );
                    }
                    pause(early_pause(early), shutdown);
                    continue;
                }
                early = 0;
                for lease in leases {
                    let slot = lease
                        .job
                        .worker
                        .as_deref()
                        .and_then(|w| ids.iter().position(|id| id == w))
                        .filter(|s| idle.contains(s));
                    match slot {
                        Some(s) if !shutdown.load(Ordering::Relaxed) => {
                            idle.remove(&s);
                            if let Err(mpsc::SendError(lease)) = slots[s].send(lease) {
                                let _ = client.release(lease.job.id, &lease.token);
                            }
                        }
                        // Leased while we were told to stop (or, against
                        // the protocol, for no idle slot): give it back.
                        _ => {
                            let _ = client.release(lease.job.id, &lease.token);
                        }
                    }
                }
            }
            Err(e) => {
                let refused = match refused_for_good(&e, told) {
                    // The worker refused the server (a failed handshake is
                    // `Tls` only before any server answered; later it is an
                    // outage, waited out), and the error says what to do.
                    _ if matches!(e, ApiError::Tls { .. }) => {
                        Some(format!("worker {}: {e}", config.id))
                    }
                    Some(check) => Some(format!(
                        "worker {}: the server at {} refused to lease jobs ({e}): {check}",
                        config.id,
                        client.base()
                    )),
                    None => None,
                };
                if let Some(message) = refused {
                    // Stop as at SIGTERM: jobs running now stop at their
                    // deadline, and their leases pass to other workers.
                    shutdown.store(true, Ordering::Relaxed);
                    return Err(RunError::Refused(message));
                }
                failures += 1;
                let wait = Duration::from_millis(200 * u64::from(failures.min(25)));
                say!(
                    "worker {}: cannot lease ({e}); retrying in {wait:?}",
                    config.id
                );
                pause(wait, shutdown);
            }
        }
    }
    Ok(())
}

/// A lease request the poller sends.
struct Ask {
    /// The idle slots.
    workers: Vec<String>,
    /// The process's tracer, until a request has gone through.
    tracer: Option<String>,
    /// The request's nonce: the same until an answer arrives, so a
    /// request sent again after a lost answer gets what the first leased.
    request: String,
}

/// Lease request nonces: unique to this process (its id and start time)
/// and to each request (a count).
fn next_nonce() -> String {
    static STARTED: std::sync::OnceLock<u128> = std::sync::OnceLock::new();
    static COUNT: AtomicU64 = AtomicU64::new(0);
    let started = STARTED.get_or_init(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    });
    format!(
        "{}-{started:x}-{}",
        std::process::id(),
        COUNT.fetch_add(1, Ordering::Relaxed)
    )
}

/// Lease requests on a thread of their own. A long poll (up to
/// `wait_secs`) blocks in its request and cannot be interrupted, so at
/// SIGTERM an idle worker stops waiting for it instead of holding its
/// exit for the rest of the poll (`docker stop` kills after 10 s). An
/// answer is handed over only to a dispatcher that takes it (a rendezvous
/// channel: none waits in a buffer to be dropped), and leases that arrive
/// after dispatch stopped listening are given back; a request still open
/// when the process exits is dropped with its connection, and the server
/// ends the poll with it.
struct Poller {
    requests: mpsc::Sender<Ask>,
    answers: mpsc::Receiver<aobake_api::client::Result<Vec<Lease>>>,
    /// Held while late leases are given back: [`Poller::finish`] waits
    /// for it.
    releasing: Arc<Mutex<()>>,
}

/// What [`Poller::lease`] got.
enum Polled {
    /// The server's answer.
    Answer(aobake_api::client::Result<Vec<Lease>>),
    /// Shutdown came first.
    Stopping,
}

impl Poller {
    /// A poller asking for jobs on `client`'s server, each request waiting
    /// up to `wait_secs` there.
    fn start(client: Client, wait_secs: u64) -> Self {
        let (requests, asked) = mpsc::channel::<Ask>();
        let (answer, answers) = mpsc::sync_channel(0);
        let releasing: Arc<Mutex<()>> = Arc::default();
        let held = releasing.clone();
        // Detached, not scoped: the process must not wait for a poll.
        std::thread::spawn(move || {
            for Ask {
                workers,
                tracer,
                request,
            } in asked
            {
                let leased =
                    client.lease_many(&workers, wait_secs, tracer.as_deref(), Some(&request));
                // Held through the hand-over: `finish` drops the receiver,
                // then waits while the leases it refused are given back.
                // (An answer that arrives in the instant between `finish`
                // and the process's exit is not given back: its leases
                // expire.)
                let _releasing = held.lock().unwrap_or_else(|e| e.into_inner());
                if let Err(mpsc::SendError(Ok(late))) = answer.send(leased) {
                    for lease in late {
                        if let Err(e) = client.release(lease.job.id, &lease.token) {
                            say!(
                                "cannot give back job {} leased as the worker stopped ({e}); its lease will expire",
                                lease.job.id
                            );
                        }
                    }
                }
            }
        });
        Self {
            requests,
            answers,
            releasing,
        }
    }

    /// Leases for the slots `workers` (telling the server `tracer`), unless
    /// `shutdown` comes first.
    fn lease(
        &self,
        workers: Vec<String>,
        tracer: Option<String>,
        request: &str,
        shutdown: &AtomicBool,
    ) -> Result<Polled, RunError> {
        let gone = || RunError::Setup("the lease thread stopped".to_owned());
        let ask = Ask {
            workers,
            tracer,
            request: request.to_owned(),
        };
        self.requests.send(ask).map_err(|_| gone())?;
        loop {
            match self.answers.recv_timeout(Duration::from_millis(100)) {
                Ok(answer) => return Ok(Polled::Answer(answer)),
                Err(mpsc::RecvTimeoutError::Timeout) if shutdown.load(Ordering::Relaxed) => {
                    return Ok(Polled::Stopping);
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => return Err(gone()),
            }
        }
    }

    /// Stops listening; waits while leases that came too late are being
    /// given back (not for an open poll).
    fn finish(self) {
        let Self {
            requests,
            answers,
            releasing,
        } = self;
        drop((requests, answers));
        drop(releasing.lock());
    }
}

/// Sends finished jobs' completions, all that are waiting in one request,
/// and tells each slot its answer; ends when every slot has ended.
fn complete_batches(client: &Client, patience: Patience<'_>, finished: &mpsc::Receiver<Finished>) {
    while let Ok(first) = finished.recv() {
        let mut batch = vec![first];
        batch.extend(finished.try_iter().take(MAX_BATCH - 1));
        let items: Vec<JobCompletion> = batch.iter().map(|f| f.item.clone()).collect();
        match patience.call(|| client.complete_many(&items)) {
            Ok(results) => {
                let mut results = results.into_iter();
                for f in batch {
                    let answer = match results.next() {
                        // The server keeps no result of a job that is no
                        // longer this worker's: say why that can be.
                        Some(Err(e)) if e.is_lease_lost() => Err(format!(
                            "{e} (the lease is no longer this worker's: the bake was cancelled, or the lease ran out and the job went to another worker)"
                        )),
                        Some(r) => r.map_err(|e| e.to_string()),
                        None => Err("the server gave no answer for it".to_owned()),
                    };
                    let _ = f.answer.send(answer);
                }
            }
            Err(e) => {
                for f in batch {
                    let _ = f.answer.send(Err(e.to_string()));
                }
            }
        }
    }
}

/// Uploads a finished job's outputs and hands its completion to the
/// completer; returns the server's answer for it.
fn deliver(
    client: &Client,
    patience: Patience<'_>,
    job: i64,
    token: &str,
    out: JobOutput,
    finished: &mpsc::Sender<Finished>,
) -> Result<(), String> {
    let outputs = out
        .outputs
        .iter()
        .map(|o| {
            patience
                .call(|| client.put_blob(&o.bytes))
                .map(|digest| OutputRef {
                    name: o.name.clone(),
                    digest,
                })
        })
        .collect::<Result<Vec<OutputRef>, ApiError>>()
        .map_err(|e| e.to_string())?;
    let timings = serde_json::to_value(out.timings).unwrap_or_default();
    let (answer, heard) = mpsc::channel();
    let item = JobCompletion {
        job,
        token: token.to_owned(),
        completion: Completion { outputs, timings },
    };
    finished
        .send(Finished { item, answer })
        .map_err(|_| "the completer has ended".to_owned())?;
    heard
        .recv()
        .map_err(|_| "the completer gave no answer".to_owned())?
}

/// Stop requests shared by the compute and heartbeat threads.
#[derive(Debug, Default)]
struct Flags {
    /// The lease is gone or the bake was cancelled: drop the job.
    lost: AtomicBool,
    /// Why the server said to stop (`the bake was cancelled`, or failed
    /// by another job), once it did, as against a lease refused (409).
    called_off: std::sync::OnceLock<String>,
    /// Shutdown past its deadline: stop and give the lease back.
    release: AtomicBool,
    /// The job finished; the heartbeat thread ends.
    done: AtomicBool,
    progress: AtomicU64,
}

struct Sink<'a> {
    client: &'a Client,
    patience: Patience<'a>,
    job: i64,
    token: &'a str,
    flags: &'a Flags,
    fault: Option<&'a str>,
    /// Checkpoints are saved at most this often.
    every: Duration,
    /// When the last checkpoint was saved (the job's start before any).
    last_saved: Instant,
}

impl Sink<'_> {
    /// Whether to stop now: the lease is lost or shutdown asks for it.
    fn stop(&self) -> Result<(), Stop> {
        if let Some(why) = self.flags.called_off.get() {
            return Err(Stop(why.clone()));
        }
        if self.flags.lost.load(Ordering::Relaxed) {
            return Err(Stop(
                "the lease was lost: it expired and was taken back, or the bake was cancelled"
                    .into(),
            ));
        }
        if self.flags.release.load(Ordering::Relaxed) {
            return Err(Stop("shutting down".into()));
        }
        Ok(())
    }
}

impl JobSink for Sink<'_> {
    fn checkpoint(&mut self, checkpoint: Checkpoint) -> Result<(), Stop> {
        if self.fault == Some("slow") {
            std::thread::sleep(Duration::from_millis(300));
        }
        // Too soon after the last one: not worth a save (the next attempt
        // resumes from the last saved checkpoint, with the same result).
        // A stop asked for is saved first, so the work is kept.
        let asked_to_stop = self.stop().is_err();
        if self.last_saved.elapsed() < self.every && !asked_to_stop {
            return Ok(());
        }
        self.last_saved = Instant::now();
        let saved = self.client.put_blob(&checkpoint.data).and_then(|blob| {
            self.client.checkpoint(
                self.job,
                self.token,
                &CheckpointRef {
                    step: checkpoint.step.clone(),
                    cursor: checkpoint.cursor as i64,
                    blob,
                },
            )
        });
        match saved {
            Ok(()) => {
                if self.fault == Some("after_checkpoint") {
                    say!("fault injected after checkpoint {}", checkpoint.cursor);
                    std::process::abort();
                }
            }
            Err(e) if e.is_lease_lost() => {
                self.flags.lost.store(true, Ordering::Relaxed);
            }
            // A checkpoint that cannot be saved costs only the work since
            // the last one; the job goes on.
            Err(e) => say!("job {}: checkpoint not saved: {e}", self.job),
        }
        self.stop()
    }

    fn progress(&mut self, done: u64, _total: u64) {
        self.flags.progress.store(done, Ordering::Relaxed);
    }

    fn save_part(&mut self, bytes: &[u8]) -> Option<String> {
        match self.client.put_blob(bytes) {
            Ok(digest) => Some(digest),
            // The job keeps the part and offers it again at its next
            // checkpoint; until then no checkpoint is recorded.
            Err(e) => {
                say!("job {}: checkpoint part not saved: {e}", self.job);
                None
            }
        }
    }

    fn load_part(&mut self, digest: &str) -> Result<Vec<u8>, JobError> {
        self.patience
            .call(|| self.client.get_blob(digest))
            .map_err(|e| JobError::Failed(format!("cannot fetch checkpoint part {digest}: {e}")))
    }
}

fn inputs(
    client: &Client,
    patience: Patience<'_>,
    lease: &Lease,
    cache: &InputCache,
) -> Result<Arc<BakeInputs>, JobError> {
    if let Some(i) = cache.lock().expect("cache lock").get(&lease.bake.id) {
        return Ok(i.clone());
    }
    let fetch = |i: usize| -> Result<UploadBytes, JobError> {
        let u = &lease.uploads[i];
        let blob = patience
            .call(|| client.get_blob(&u.digest))
            .map_err(|e| JobError::Failed(format!("cannot fetch upload {}: {e}", u.digest)))?;
        UploadBytes::from_blob(&blob, u.bundle).map_err(|e| JobError::Invalid(e.to_string()))
    };
    if lease.uploads.is_empty() {
        return Err(JobError::Invalid("the lease names no character".into()));
    }
    let character = fetch(0)?;
    let clips = (1..lease.uploads.len())
        .map(fetch)
        .collect::<Result<Vec<_>, _>>()?;
    let loaded = BakeInputs::load(&character, &clips, &Limits::default())
        .map_err(|e| JobError::Invalid(e.to_string()))?;
    let loaded = Arc::new(loaded);
    let mut c = cache.lock().expect("cache lock");
    if c.len() >= 4 {
        c.clear();
    }
    c.insert(lease.bake.id, loaded.clone());
    Ok(loaded)
}

fn execute(
    client: &Client,
    patience: Patience<'_>,
    config: &WorkerConfig,
    lease: &Lease,
    flags: &Flags,
    cache: &InputCache,
) -> Result<JobOutput, JobError> {
    let spec: JobSpec = serde_json::from_value(lease.job.spec.clone())
        .map_err(|e| JobError::Invalid(format!("job spec: {e}")))?;
    let params = BakeParams::from_canonical(&lease.bake.params)
        .map_err(|e| JobError::Invalid(format!("bake params: {e}")))?;
    let inputs = inputs(client, patience, lease, cache)?;
    let bake = Bake::new(&inputs, params)?;
    let mut deps = Vec::with_capacity(lease.inputs.len());
    for d in &lease.inputs {
        let mut out = JobOutput {
            timings: serde_json::from_value(d.timings.clone()).unwrap_or_default(),
            outputs: Vec::new(),
        };
        // Only what the job reads (not, say, a cubemap ground's truth for
        // a preview).
        for o in d.outputs.iter().filter(|o| spec.reads(&o.name)) {
            let bytes = patience
                .call(|| client.get_blob(&o.digest))
                .map_err(|e| match e.status() {
                    // Stored when its job completed, gone since (an emptied
                    // bucket, an expired object): every attempt would fail
                    // alike, so the bake fails now, saying how to go on.
                    Some(404) => JobError::Invalid(format!(
                        "input {} ({}) is gone from the blob store: `aobake retry {}` runs the job that made it again",
                        o.name, o.digest, lease.job.bake_id
                    )),
                    _ => JobError::Failed(format!("cannot fetch {}: {e}", o.name)),
                })?;
            out.outputs.push(Output {
                name: o.name.clone(),
                bytes,
            });
        }
        deps.push(out);
    }
    let resume = match &lease.job.checkpoint {
        Some(c) => match patience.call(|| client.get_blob(&c.blob)) {
            Ok(data) => Some(Checkpoint {
                step: c.step.clone(),
                cursor: c.cursor as u64,
                data,
            }),
            // Gone from the blob store (emptied, expired): the job starts
            // over, as it would without one.
            Err(e) if e.status() == Some(404) => {
                say!(
                    "job {}: its checkpoint is gone from the blob store; starting over",
                    lease.job.id
                );
                None
            }
            Err(e) => {
                return Err(JobError::Failed(format!(
                    "cannot fetch the checkpoint: {e}"
                )));
            }
        },
        None => None,
    };
    let dep_refs: Vec<&JobOutput> = deps.iter().collect();
    let mut sink = Sink {
        client,
        patience,
        job: lease.job.id,
        token: &lease.token,
        flags,
        fault: config.fault.as_deref(),
        every: Duration::from_secs_f64(config.checkpoint_secs.max(0.0)),
        last_saved: Instant::now(),
    };
    match spec {
        JobSpec::Preview => match crate::gpu::Gpu::shared() {
            // A machine with no adapter at all (no GPU, no Mesa) cannot
            // draw, and another attempt there will not either: the bake's
            // asset is good, so the job ends saying why there are no
            // previews rather than failing the bake.
            Err(e @ crate::gpu::GpuError::NoAdapter(_)) => {
                say!("no previews: {e}");
                Ok(aobake_core::bake::preview::unavailable(&e.to_string()))
            }
            Err(e) => Err(JobError::Failed(format!("no GPU for previews: {e}"))),
            Ok(gpu) => {
                let mut renderer = crate::gpu::PreviewRenderer::new(gpu)
                    .map_err(|e| JobError::Failed(format!("the preview renderer: {e}")))?;
                bake.preview(&dep_refs, &mut renderer)
            }
        },
        // The stages after the tracing run while few jobs are left to
        // share the machine: on every core. The bytes do not depend on the
        // thread count (tested in core).
        JobSpec::Fit | JobSpec::Unseen { .. } | JobSpec::Evaluate | JobSpec::Assemble => {
            match wide_pool() {
                Some(pool) => pool.install(|| bake.run_job(&spec, &dep_refs, resume, &mut sink)),
                None => bake.run_job(&spec, &dep_refs, resume, &mut sink),
            }
        }
        JobSpec::Sample { .. }
        | JobSpec::Face { .. }
        | JobSpec::Slab { .. }
        | JobSpec::PreviewTruth { .. } => bake.run_job(&spec, &dep_refs, resume, &mut sink),
    }
}

/// A thread pool of every core, for the jobs that follow a bake's tracing
/// (a fit, its unseen-clip folds, evaluation, assembly). The tracing jobs
/// keep the worker's own threads (`RAYON_NUM_THREADS`: `aobake serve`
/// gives each local worker its share of the cores), which is right while
/// there are many of them; a fit or an evaluation often runs alone, with
/// the other workers idle. `None` when the worker has every core already.
fn wide_pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if cores <= rayon::current_num_threads() {
            return None;
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(cores)
            .thread_name(|i| format!("fit-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// How long a worker keeps trying a call while the server is away (a
/// restart, a rolling update, a database or blob store failing over):
/// finished work is worth the wait, and a lease outlives a short outage.
/// A completion that arrives after the job was leased again gets 409,
/// which ends the tries.
const RETRY_FOR: Duration = Duration::from_secs(300);

/// Tries calls again through an outage ([`aobake_api::client::retry`]):
/// for up to [`RETRY_FOR`], and once shutdown is asked for, for at most
/// its deadline more, so that a worker still stops in time. It says why it
/// waits at the first retry and every 30 s after.
#[derive(Debug, Clone, Copy)]
struct Patience<'a> {
    shutdown: &'a AtomicBool,
    grace: Duration,
}

impl<'a> Patience<'a> {
    fn new(shutdown: &'a AtomicBool, config: &WorkerConfig) -> Self {
        Self {
            shutdown,
            grace: Duration::from_secs(config.shutdown_secs),
        }
    }

    fn call<T>(&self, call: impl FnMut() -> Result<T, ApiError>) -> Result<T, ApiError> {
        // When shutdown was first seen during these tries.
        let stopping: std::cell::Cell<Option<Instant>> = std::cell::Cell::default();
        let since_stop = || {
            self.shutdown.load(Ordering::Relaxed).then(|| {
                let at = stopping.get().unwrap_or_else(Instant::now);
                stopping.set(Some(at));
                at.elapsed()
            })
        };
        let keep_on = || since_stop().is_none_or(|s| s < self.grace);
        let mut said: Option<Instant> = None;
        let waiting = |e: &ApiError, left: Duration| {
            if said.is_none_or(|t| t.elapsed() >= Duration::from_secs(30)) {
                // A stopping worker tries for what is left of its
                // --shutdown-secs, not the whole window.
                match since_stop() {
                    Some(s) => say!(
                        "retrying (for up to {} s more: the worker is stopping) after: {e}",
                        left.min(self.grace.saturating_sub(s)).as_secs()
                    ),
                    None => say!("retrying (for up to {} s more) after: {e}", left.as_secs()),
                }
                said = Some(Instant::now());
            }
        };
        aobake_api::client::retry(
            RETRY_FOR,
            Duration::from_millis(500),
            keep_on,
            waiting,
            call,
        )
    }
}

fn run_leased(
    client: &Client,
    config: &WorkerConfig,
    lease: Lease,
    shutdown: &AtomicBool,
    cache: &InputCache,
    finished: &mpsc::Sender<Finished>,
) {
    let job = lease.job.id;
    let flags = Flags::default();
    let started = Instant::now();
    let patience = Patience::new(shutdown, config);
    let result = std::thread::scope(|scope| {
        // Heartbeats run off the compute thread, so a long pose never
        // starves the lease.
        scope.spawn(|| {
            let period = Duration::from_secs_f64(config.heartbeat_secs.max(0.05));
            // Progress goes out within a second of moving, so the bar
            // follows a job whose steps are shorter than the period (a
            // cubemap face's batches, a fit's steps); without a change
            // the heartbeat keeps its period.
            let prompt = PROGRESS_EVERY.min(period);
            let mut sent = 0;
            let mut shutdown_since: Option<Instant> = None;
            // Failing heartbeats are said once, then every 30 s, and their
            // end once: an outage does not fill the log a line a second.
            let mut failing: Option<(Instant, Instant)> = None;
            while !flags.done.load(Ordering::Relaxed) {
                let tick = Instant::now();
                while !flags.done.load(Ordering::Relaxed) {
                    let waited = tick.elapsed();
                    if waited >= period
                        || waited >= prompt && flags.progress.load(Ordering::Relaxed) != sent
                    {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
                if flags.done.load(Ordering::Relaxed) {
                    break;
                }
                if shutdown.load(Ordering::Relaxed) {
                    let since = *shutdown_since.get_or_insert_with(Instant::now);
                    if since.elapsed() > Duration::from_secs(config.shutdown_secs) {
                        flags.release.store(true, Ordering::Relaxed);
                    }
                }
                let progress = flags.progress.load(Ordering::Relaxed);
                sent = progress;
                let beat = client.heartbeat(job, &lease.token, progress);
                if let (Ok(_), Some((since, _))) = (&beat, failing) {
                    say!(
                        "job {job}: heartbeats get through again after {:.0} s",
                        since.elapsed().as_secs_f64()
                    );
                    failing = None;
                }
                match beat {
                    Ok(reply) => {
                        if reply.stop {
                            let why = match reply.bake_state {
                                Some(BakeState::Cancelled) => "the bake was cancelled".to_owned(),
                                Some(BakeState::Failed) => {
                                    "the bake failed (another of its jobs died)".to_owned()
                                }
                                Some(state) => format!("the bake is {}", state.as_str()),
                                None => "the bake ended".to_owned(),
                            };
                            let _ = flags.called_off.set(why);
                            flags.lost.store(true, Ordering::Relaxed);
                        }
                    }
                    Err(e) if e.is_lease_lost() => flags.lost.store(true, Ordering::Relaxed),
                    Err(e) => match &mut failing {
                        None => {
                            say!("job {job}: heartbeat failed: {e}");
                            failing = Some((Instant::now(), Instant::now()));
                        }
                        Some((since, said)) if said.elapsed() >= Duration::from_secs(30) => {
                            say!(
                                "job {job}: heartbeats failing for {:.0} s: {e}",
                                since.elapsed().as_secs_f64()
                            );
                            *said = Instant::now();
                        }
                        Some(_) => {}
                    },
                }
            }
        });
        // A panic in a job must not leave the heartbeat thread extending
        // the lease forever: it becomes a retryable failure.
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            execute(client, patience, config, &lease, &flags, cache)
        }))
        .unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            Err(JobError::Failed(format!("the job panicked: {what}")))
        });
        // The outputs go up and the completion waits for its batch while
        // the heartbeats go on: a slow store or a long batch does not
        // lose the lease.
        let r = r.map(|out| deliver(client, patience, job, &lease.token, out, finished));
        flags.done.store(true, Ordering::Relaxed);
        r
    });
    let spec = &lease.job.spec;
    match result {
        Ok(done) => match done {
            Ok(()) => say!(
                "job {job} ({}) done in {:.2} s",
                spec["kind"],
                started.elapsed().as_secs_f64()
            ),
            Err(e) => say!("job {job}: completion refused: {e}"),
        },
        Err(JobError::Stopped(Stop(why))) => {
            // Give the lease back if it is still ours (a stop asked by the
            // server or by shutdown); a lost lease answers 409, harmlessly.
            let _ = client.release(job, &lease.token);
            say!("job {job}: stopped ({why})");
        }
        Err(e) => {
            say!("job {job} failed: {e}");
            let why = e.to_string();
            if let Err(e) = patience.call(|| client.fail(job, &lease.token, &why, e.retryable())) {
                say!("job {job}: failure not recorded: {e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stopping worker tries a call through an outage for its
    /// `--shutdown-secs`, not the whole 5-minute window.
    #[test]
    fn a_stopping_worker_gives_up_after_its_grace() {
        let shutdown = AtomicBool::new(true);
        let patience = Patience {
            shutdown: &shutdown,
            grace: Duration::from_secs(1),
        };
        let started = Instant::now();
        let mut tries = 0;
        let answer: Result<(), ApiError> = patience.call(|| {
            tries += 1;
            Err(ApiError::Transport {
                base: "http://127.0.0.1:1".into(),
                message: "connection refused".into(),
            })
        });
        assert!(answer.is_err());
        assert!(tries >= 2, "it tried again: {tries}");
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{:?}",
            started.elapsed()
        );
    }
}
