//! What the service knows (DESIGN §8): uploads, bakes, their jobs (the
//! queue), workers and tokens, behind one small trait. Bytes live in
//! [`crate::blobs`], never here.
//!
//! The queue: a job is `blocked` until its dependencies complete, then
//! `available`; a worker's lease makes it `running` with a fresh lease
//! token and counts an attempt; heartbeats extend the lease; `complete`
//! with the current token makes it `completed` in the same transaction
//! that unblocks its dependents and advances the bake. A lease that
//! expires, or a failure that may pass on retry, makes it `retryable`
//! (with exponential backoff and jitter after a failure) until its
//! attempts run out: then it is `dead` and its bake `failed`. Every time
//! comes from the database clock.
//!
//! The state machine is written once (`queue`) over the SQL both engines
//! speak; [`SqliteStore`], the embedded default, and [`PgStore`] bring
//! only their differences. Both run one shared test suite (`suite`).

mod postgres;
mod queue;
mod rows;
mod sqlite;
#[cfg(test)]
pub(crate) mod suite;

pub use postgres::PgStore;
pub use sqlite::SqliteStore;

pub use aobake_api::{
    Action, BakeRow, BakeState, CheckpointRef, Completion, JobCompletion, JobRow, JobState, Lease,
    OutputRef, UploadRef, UploadRow, WorkerRow,
};

/// A failed store operation.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The lease token is not the job's current one (the lease expired and
    /// the job moved on, or the job was cancelled).
    #[error("the lease is no longer held: {0}")]
    LeaseLost(String),
    /// The bake or job does not exist.
    #[error("not found: {0}")]
    NotFound(String),
    /// The request conflicts with the bake's state.
    #[error("{0}")]
    Conflict(String),
    /// The token was revoked (at this time, ms since the epoch), and a
    /// revoked secret is never valid again.
    #[error("the token was revoked (at {0} ms since the epoch) and stays revoked")]
    Revoked(i64),
    /// The database failed. (Its message is this error's own, not also
    /// its source's: a chain printed whole says it once.)
    #[error("database: {0}")]
    Database(sqlx::Error),
    /// The schema could not be migrated.
    #[error("migration: {0}")]
    Migrate(sqlx::migrate::MigrateError),
    /// A stored document did not parse.
    #[error("stored JSON: {0}")]
    Json(serde_json::Error),
}

/// Whether `e` says the database could not be reached (down, restarting,
/// its connections gone), not that a query failed.
pub(crate) fn unreachable(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Io(_)
        | sqlx::Error::PoolTimedOut
        | sqlx::Error::PoolClosed
        | sqlx::Error::WorkerCrashed
        | sqlx::Error::Tls(_) => true,
        // SQLSTATE classes 08 (connection exception) and 57P (operator
        // intervention: shutting down, cannot connect now).
        sqlx::Error::Database(d) => d
            .code()
            .is_some_and(|c| c.starts_with("08") || c.starts_with("57P")),
        _ => false,
    }
}

/// The database's outages as this process sees them, at each connection
/// it asks for: the first one it gets after it could not says so in the
/// log, with how long since the first request that could not
/// (`the database answers again, after N s`), however the outage was
/// noticed (a request's 503, the reaper, a heartbeat).
#[derive(Debug, Clone, Default)]
pub(crate) struct Outages(std::sync::Arc<std::sync::Mutex<Option<std::time::Instant>>>);

impl Outages {
    /// `result`, of an ask for a connection that began at `asked`, after
    /// noting whether the database answered.
    pub(crate) fn heard<T>(
        &self,
        asked: std::time::Instant,
        result: std::result::Result<T, sqlx::Error>,
    ) -> std::result::Result<T, sqlx::Error> {
        let mut down = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match &result {
            Err(e) if unreachable(e) => {
                down.get_or_insert(asked);
            }
            Err(_) => {}
            Ok(_) => {
                if let Some(since) = down.take() {
                    log_line!(
                        "the database answers again, after {:.0} s",
                        since.elapsed().as_secs_f64()
                    );
                }
            }
        }
        result
    }
}

impl From<sqlx::Error> for StoreError {
    fn from(e: sqlx::Error) -> Self {
        Self::Database(e)
    }
}

impl From<sqlx::migrate::MigrateError> for StoreError {
    fn from(e: sqlx::migrate::MigrateError) -> Self {
        Self::Migrate(e)
    }
}

impl From<serde_json::Error> for StoreError {
    fn from(e: serde_json::Error) -> Self {
        Self::Json(e)
    }
}

/// Results of store operations.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// A job of a bake to create.
#[derive(Debug, Clone, PartialEq)]
pub struct NewJob {
    /// `sample`, `fit`, …
    pub kind: String,
    /// The spec.
    pub spec: serde_json::Value,
    /// Units of work.
    pub work: i64,
    /// Indices of dependencies (earlier jobs).
    pub deps: Vec<usize>,
}

/// A bake to create.
#[derive(Debug, Clone, PartialEq)]
pub struct NewBake {
    /// The bake key.
    pub key: String,
    /// Character digest.
    pub character: String,
    /// Clip digests.
    pub clips: Vec<String>,
    /// Method name.
    pub method: String,
    /// Fully defaulted parameters.
    pub params: serde_json::Value,
    /// Priority.
    pub priority: i64,
    /// Its job graph.
    pub jobs: Vec<NewJob>,
    /// Leases allowed per job.
    pub max_attempts: i64,
}

/// What a heartbeat found.
#[derive(Debug, Clone)]
pub struct Beat {
    /// The job should stop: its bake is no longer active.
    pub stop: bool,
    /// The job's progress changed (its bake's listeners are told).
    pub moved: bool,
    /// The job's bake.
    pub bake: BakeRow,
}

/// A token as stored (its hash, never the secret).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TokenRow {
    /// Name.
    pub name: String,
    /// Scopes.
    pub scopes: Vec<String>,
    /// Milliseconds since the epoch.
    pub created_at: i64,
    /// When it stops being valid (ms since the epoch); `None`: never.
    pub expires_at: Option<i64>,
    /// When a request last used it (ms since the epoch, to the minute).
    pub last_used_at: Option<i64>,
}

impl TokenRow {
    /// When it expired, if it had by `now` (ms since the epoch): what
    /// every check of a token's time asks.
    pub fn expired(&self, now: i64) -> Option<i64> {
        self.expires_at.filter(|&at| at <= now)
    }
}

/// How leases and retries behave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueuePolicy {
    /// A lease lasts this long unless heartbeated.
    pub lease_ms: i64,
    /// First retry delay after a failure; doubles per attempt.
    pub backoff_ms: i64,
    /// Longest retry delay.
    pub max_backoff_ms: i64,
    /// Failures of one worker on one bake before it is kept off the bake.
    pub worker_failures: i64,
    /// Leases a job gets before it is dead.
    pub max_attempts: i64,
}

impl QueuePolicy {
    /// The delay before retry `attempt` (1-based): doubling from the base,
    /// at most the cap, times a jitter in [0.5, 1.5) so that jobs failed
    /// together do not come back together.
    pub fn backoff_ms(&self, attempt: i64) -> i64 {
        use rand::RngExt as _;
        let exp = attempt.clamp(1, 30) - 1;
        let base = self
            .backoff_ms
            .saturating_mul(1i64 << exp)
            .min(self.max_backoff_ms);
        let jitter: f64 = rand::rng().random_range(0.5..1.5);
        (base as f64 * jitter) as i64
    }
}

/// A new lease token: 128 random bits in hex.
fn lease_token() -> String {
    use rand::RngExt as _;
    let bytes: [u8; 16] = rand::rng().random();
    aobake_core::digest::hex(&bytes)
}

impl Default for QueuePolicy {
    fn default() -> Self {
        Self {
            lease_ms: 30_000,
            backoff_ms: 1_000,
            max_backoff_ms: 60_000,
            worker_failures: 3,
            max_attempts: 5,
        }
    }
}

/// The store: metadata and the queue.
#[async_trait::async_trait]
pub trait Store: Send + Sync + std::fmt::Debug + 'static {
    /// Records an upload; `false` when it was there already.
    async fn put_upload(&self, upload: &UploadRow) -> Result<bool>;
    /// Every upload, oldest first.
    async fn uploads(&self) -> Result<Vec<UploadRow>>;
    /// Forgets an unfinished job's checkpoint `blob` (gone from the blob
    /// store): its next attempt starts over. A newer checkpoint, saved
    /// since, is kept.
    async fn forget_checkpoint(&self, job: i64, blob: &str) -> Result<()>;
    /// An upload by digest and kind (`character` or `clips`).
    async fn upload(&self, digest: &str, kind: &str) -> Result<Option<UploadRow>>;
    /// Creates a bake and its jobs; jobs without dependencies start
    /// `available`.
    async fn create_bake(&self, bake: &NewBake) -> Result<BakeRow>;
    /// A bake by id.
    async fn bake(&self, id: i64) -> Result<Option<BakeRow>>;
    /// The bakes with this key that are done or still active, done first,
    /// newest first (at most 16): a done bake whose asset was lost is
    /// passed over for the next.
    async fn bakes_for_key(&self, key: &str) -> Result<Vec<BakeRow>>;
    /// Bakes, newest first, optionally of one character and method.
    async fn bakes(
        &self,
        character: Option<&str>,
        method: Option<&str>,
        limit: i64,
    ) -> Result<Vec<BakeRow>>;
    /// A bake's jobs in graph order.
    async fn jobs(&self, bake: i64) -> Result<Vec<JobRow>>;
    /// Leases up to one ready job for each of `workers` (a worker
    /// process's idle slots), most urgent first, in one transaction: the
    /// leases come in the order of `workers`, each job's `worker` naming
    /// its slot, and slots left over get nothing.
    async fn lease_many(&self, workers: &[String], policy: &QueuePolicy) -> Result<Vec<Lease>> {
        self.lease_batch(workers, None, policy).await
    }
    /// [`Store::lease_many`] for a request with a nonce (`request`): the
    /// same request sent again, after its answer was lost, gets the jobs
    /// it leased and that still run under its slots, with the same tokens
    /// and attempts and their leases renewed, beside new jobs for its
    /// other slots.
    async fn lease_batch(
        &self,
        workers: &[String],
        request: Option<&str>,
        policy: &QueuePolicy,
    ) -> Result<Vec<Lease>>;
    /// Leases the most urgent ready job for `worker`, if any.
    async fn lease(&self, worker: &str, policy: &QueuePolicy) -> Result<Option<Lease>> {
        Ok(self
            .lease_many(&[worker.to_owned()], policy)
            .await?
            .into_iter()
            .next())
    }
    /// Extends a lease and records progress; says whether the job should
    /// stop (its bake was cancelled; paused does not stop it) and whether
    /// its progress moved.
    async fn heartbeat(
        &self,
        job: i64,
        token: &str,
        progress: i64,
        policy: &QueuePolicy,
    ) -> Result<Beat>;
    /// Records a checkpoint for the next attempt.
    async fn checkpoint(&self, job: i64, token: &str, checkpoint: &CheckpointRef) -> Result<()>;
    /// Completes several jobs in one transaction, each as `complete`
    /// would: one answer per item, in order, so a lost lease refuses its
    /// own item only. The outer error is the database's, for all of them.
    async fn complete_many(&self, items: &[JobCompletion]) -> Result<Vec<Result<BakeRow>>>;
    /// Completes a job with its outputs; returns its bake afterwards.
    async fn complete(&self, job: i64, token: &str, completion: &Completion) -> Result<BakeRow> {
        let item = JobCompletion {
            job,
            token: token.to_owned(),
            completion: completion.clone(),
        };
        self.complete_many(std::slice::from_ref(&item))
            .await?
            .pop()
            .unwrap_or_else(|| Err(StoreError::NotFound(format!("job {job}"))))
    }
    /// Fails an attempt; `retryable` false kills the job at once.
    async fn fail(
        &self,
        job: i64,
        token: &str,
        error: &str,
        retryable: bool,
        policy: &QueuePolicy,
    ) -> Result<BakeRow>;
    /// Gives a lease back without counting an attempt (graceful shutdown).
    async fn release(&self, job: i64, token: &str) -> Result<()> {
        self.release_unless_renewed(job, token, None).await
    }
    /// [`Store::release`]; with `expires_at`, only while the lease still
    /// expires then: a lease renewed since (the same lease request, sent
    /// again, got it back) is kept.
    async fn release_unless_renewed(
        &self,
        job: i64,
        token: &str,
        expires_at: Option<i64>,
    ) -> Result<()>;
    /// Makes jobs whose leases expired retryable (or dead); returns how
    /// many.
    async fn reap(&self) -> Result<u64>;
    /// Cancels, pauses, resumes or retries a bake.
    async fn control(&self, bake: i64, action: Action) -> Result<BakeRow>;
    /// Queues a bake again, as [`Action::Retry`] does for a failed or
    /// cancelled one (its unfinished jobs with fresh attempts), with its
    /// completed jobs `lost` run again: the blob store lost their outputs.
    /// A done bake is queued again only for lost jobs. Their work counts
    /// as reached, so the bake's progress does not move back; what the
    /// bake published from them is forgotten until they publish it again.
    async fn retry(&self, bake: i64, lost: &[i64]) -> Result<BakeRow>;
    /// Sets a bake's priority.
    async fn set_priority(&self, bake: i64, priority: i64) -> Result<BakeRow>;
    /// Records that `workers` are alive and waiting for a job, in one
    /// transaction (a worker process's idle slots, at each long poll).
    async fn workers_idle(&self, workers: &[String]) -> Result<()>;
    /// Forgets workers not seen for `gone_ms` that hold no running job;
    /// returns how many.
    async fn forget_workers(&self, gone_ms: i64) -> Result<u64>;
    /// Records what casts a worker's rays (`cpu`, or `gpu: ADAPTER`), which
    /// a process tells in its first lease request: the worker (re)started
    /// now, so its `started_at` is now, also under a name used before.
    async fn worker_tracer(&self, worker: &str, tracer: &str) -> Result<()>;
    /// Records that `workers` have stopped (a worker process exiting
    /// gracefully): listed as `stopped` at once, with no job, not idle GPU
    /// workers that tracing jobs wait for, and not other workers that a
    /// bake kept off a failing worker waits for; no lease goes to them
    /// after, and a job still leased to them (leased as the process went)
    /// is given back, its attempt not counted. A worker id that polls
    /// again is idle again.
    async fn workers_stopped(&self, workers: &[String]) -> Result<()>;
    /// Within one long poll, after [`Store::workers_idle`] began it:
    /// records again that `workers` are waiting, unless one of them has
    /// said it stopped since (then `false`, and nothing is changed: the
    /// process no longer listens for this poll's answer).
    async fn workers_still_waiting(&self, workers: &[String]) -> Result<bool>;
    /// Every worker, most recently seen first; one not seen for
    /// `gone_after_ms` is `stopped`, with no job (it exited, was killed
    /// or is cut off: a live worker polls or heartbeats well within a
    /// lease), and a busy one whose job is no longer its running job (the
    /// bake cancelled, the lease taken back) is `idle`.
    async fn workers(&self, gone_after_ms: i64) -> Result<Vec<WorkerRow>>;
    /// Stores a token's hash; [`StoreError::Revoked`] for one revoked
    /// before.
    async fn create_token(&self, hash: &str, name: &str, scopes: &[String]) -> Result<()> {
        self.create_token_until(hash, name, scopes, None).await
    }
    /// [`Store::create_token`] valid until `expires_at` (ms since the
    /// epoch; `None`: no end).
    async fn create_token_until(
        &self,
        hash: &str,
        name: &str,
        scopes: &[String],
        expires_at: Option<i64>,
    ) -> Result<()>;
    /// A token by hash, expired or not (the caller says which).
    async fn token(&self, hash: &str) -> Result<Option<TokenRow>>;
    /// Records that the token was used at `at` (ms since the epoch, the
    /// caller's clock), unless its last use on record is within a minute
    /// of it.
    async fn token_used(&self, hash: &str, at: i64) -> Result<()>;
    /// Every token, newest first, by hash (the secrets are not stored).
    async fn tokens(&self) -> Result<Vec<(String, TokenRow)>>;
    /// Deletes a token: from its next request on it is refused (401).
    /// Revoked (`revoke`: an admin's `DELETE /v1/tokens/{id}`), it can
    /// never be created again, nor is it valid if a create raced the
    /// revocation; a token `serve` rotates out at its next start is only
    /// deleted (an operator may have adopted that secret as the fleet's
    /// `AOBAKE_ADMIN_TOKEN`). Whether there was one.
    async fn delete_token(&self, hash: &str, revoke: bool) -> Result<bool>;
    /// Jobs per state, and lease expiries so far.
    async fn queue_stats(&self) -> Result<(Vec<(JobState, i64)>, i64)>;
    /// Whether the database answers.
    async fn ping(&self) -> Result<()>;
    /// Wakes `ready` whenever another process of the service may have
    /// made jobs ready (PostgreSQL's LISTEN/NOTIFY); a store that only one
    /// process uses needs nothing, since the server wakes its own waiters.
    async fn listen(&self, _ready: std::sync::Arc<tokio::sync::Notify>) -> Result<()> {
        Ok(())
    }
    /// Shares bake events among the servers on this store: a sender whose
    /// events reach every server's `events` (this one's included, in the
    /// order sent), where several servers can share the store
    /// (PostgreSQL's NOTIFY); `None` where one server owns it and
    /// broadcasts its own.
    async fn share_events(
        &self,
        _events: tokio::sync::broadcast::Sender<crate::state::BakeEvent>,
    ) -> Result<Option<tokio::sync::mpsc::UnboundedSender<crate::state::BakeEvent>>> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::QueuePolicy;

    #[test]
    fn backoff_doubles_up_to_the_cap_with_jitter() {
        let p = QueuePolicy {
            backoff_ms: 1000,
            max_backoff_ms: 60_000,
            ..QueuePolicy::default()
        };
        for (attempt, base) in [(1, 1000), (2, 2000), (3, 4000), (7, 60_000), (99, 60_000)] {
            for _ in 0..50 {
                let d = p.backoff_ms(attempt);
                assert!(d >= base / 2 && d < base * 3 / 2, "attempt {attempt}: {d}");
            }
        }
    }
}
