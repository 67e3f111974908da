//! The queue's state machine, written once over the SQL that SQLite and
//! PostgreSQL both speak. A backend ([`Backend`]) brings only what differs:
//! its connections and transactions (how a write takes its turn and how
//! durable it must be), the clock, how to list a job's dependencies, the
//! row-lock suffixes and how other servers are woken. Statements use `$n`
//! placeholders, which both drivers bind by number.
//!
//! A statement is text plus values ([`Stmt`]); [`Conn`] runs one on a
//! connection. In the text, `{now}` is the database clock in milliseconds,
//! `{deps}` the comma-separated graph indices of the dependencies of the
//! row `jobs`, and `{for_update}` / `{skip_locked}` the row-lock suffixes.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::ops::DerefMut;
use std::sync::Arc;

use aobake_core::bake::JobSpec;
use sqlx::{FromRow, postgres::PgRow, sqlite::SqliteRow};

use super::rows::{RawBake, RawJob, RawToken, RawUpload, RawWorker};
use super::{
    Action, BakeRow, BakeState, Beat, CheckpointRef, Completion, JobCompletion, JobRow, JobState,
    Lease, NewBake, QueuePolicy, Result, Store, StoreError, TokenRow, UploadRef, UploadRow,
    WorkerRow, lease_token,
};

/// A value bound to a placeholder.
#[derive(Debug, Clone)]
pub(super) enum Arg {
    Int(i64),
    OptInt(Option<i64>),
    Text(String),
    OptText(Option<String>),
    Bool(bool),
}

impl From<i64> for Arg {
    fn from(v: i64) -> Self {
        Self::Int(v)
    }
}
impl From<Option<i64>> for Arg {
    fn from(v: Option<i64>) -> Self {
        Self::OptInt(v)
    }
}
impl From<&str> for Arg {
    fn from(v: &str) -> Self {
        Self::Text(v.to_owned())
    }
}
impl From<&String> for Arg {
    fn from(v: &String) -> Self {
        Self::Text(v.clone())
    }
}
impl From<String> for Arg {
    fn from(v: String) -> Self {
        Self::Text(v)
    }
}
impl From<Option<&str>> for Arg {
    fn from(v: Option<&str>) -> Self {
        Self::OptText(v.map(str::to_owned))
    }
}
impl From<Option<String>> for Arg {
    fn from(v: Option<String>) -> Self {
        Self::OptText(v)
    }
}
impl From<bool> for Arg {
    fn from(v: bool) -> Self {
        Self::Bool(v)
    }
}

/// A statement with its dialect placeholders expanded, and its values.
#[derive(Debug, Clone)]
pub(super) struct Stmt {
    pub sql: String,
    pub args: Vec<Arg>,
}

impl Stmt {
    /// Binds the next placeholder.
    pub(super) fn bind(mut self, value: impl Into<Arg>) -> Self {
        self.args.push(value.into());
        self
    }

    /// Binds the next placeholders, one per value (see [`placeholders`]).
    pub(super) fn bind_all<T: Into<Arg>>(mut self, values: impl IntoIterator<Item = T>) -> Self {
        self.args.extend(values.into_iter().map(Into::into));
        self
    }
}

/// `n` placeholders from `$first` on, for an `IN (…)` list.
fn placeholders(first: usize, n: usize) -> String {
    (first..first + n)
        .map(|i| format!("${i}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Builds a driver's argument list from bound values.
pub(super) fn arguments<'q, DB: sqlx::Database>(args: Vec<Arg>) -> Result<DB::Arguments<'q>>
where
    i64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<i64>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    String: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<String>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    bool: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
{
    use sqlx::Arguments as _;
    let mut out = DB::Arguments::default();
    for a in args {
        match a {
            Arg::Int(v) => out.add(v),
            Arg::OptInt(v) => out.add(v),
            Arg::Text(v) => out.add(v),
            Arg::OptText(v) => out.add(v),
            Arg::Bool(v) => out.add(v),
        }
        .map_err(sqlx::Error::Encode)?;
    }
    Ok(out)
}

/// A row type that both drivers decode.
pub(super) trait Decode:
    for<'r> FromRow<'r, SqliteRow> + for<'r> FromRow<'r, PgRow> + Send + Unpin
{
}
impl<T> Decode for T where
    T: for<'r> FromRow<'r, SqliteRow> + for<'r> FromRow<'r, PgRow> + Send + Unpin
{
}

/// A connection that runs statements.
#[async_trait::async_trait]
pub(super) trait Conn: Send {
    /// Runs `s`; the rows it changed.
    async fn execute(&mut self, s: Stmt) -> Result<u64>;
    /// Every row `s` returns.
    async fn all<T: Decode>(&mut self, s: Stmt) -> Result<Vec<T>>;
    /// The first row `s` returns, if any.
    async fn optional<T: Decode>(&mut self, s: Stmt) -> Result<Option<T>>;

    /// The row `s` returns; an error when there is none.
    async fn one<T: Decode>(&mut self, s: Stmt) -> Result<T> {
        self.optional(s)
            .await?
            .ok_or(StoreError::Database(sqlx::Error::RowNotFound))
    }

    /// The first column of the first row, if any.
    async fn scalar<T>(&mut self, s: Stmt) -> Result<Option<T>>
    where
        (T,): Decode,
        T: Send,
    {
        Ok(self.optional::<(T,)>(s).await?.map(|(v,)| v))
    }
}

/// Implements [`Conn`] for a driver's connection type.
macro_rules! sql_conn {
    ($conn:ty, $db:ty) => {
        #[async_trait::async_trait]
        impl $crate::store::queue::Conn for $conn {
            async fn execute(
                &mut self,
                s: $crate::store::queue::Stmt,
            ) -> $crate::store::Result<u64> {
                let args = $crate::store::queue::arguments::<$db>(s.args)?;
                let done = sqlx::query_with::<$db, _>(&s.sql, args)
                    .execute(self)
                    .await?;
                Ok(done.rows_affected())
            }

            async fn all<T: $crate::store::queue::Decode>(
                &mut self,
                s: $crate::store::queue::Stmt,
            ) -> $crate::store::Result<Vec<T>> {
                let args = $crate::store::queue::arguments::<$db>(s.args)?;
                Ok(sqlx::query_as_with::<$db, T, _>(&s.sql, args)
                    .fetch_all(self)
                    .await?)
            }

            async fn optional<T: $crate::store::queue::Decode>(
                &mut self,
                s: $crate::store::queue::Stmt,
            ) -> $crate::store::Result<Option<T>> {
                let args = $crate::store::queue::arguments::<$db>(s.args)?;
                Ok(sqlx::query_as_with::<$db, T, _>(&s.sql, args)
                    .fetch_optional(self)
                    .await?)
            }
        }
    };
}
pub(super) use sql_conn;

/// How durable a write must be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Durability {
    /// Flushed to disk before the commit returns: what a client is told
    /// is done (an upload, a bake, a completion, a failure, a control).
    Acknowledged,
    /// May be lost in a power cut without harm: leases, heartbeats,
    /// checkpoints, reaping (a lost lease is re-leased, a lost checkpoint
    /// resumes from the one before).
    Queue,
}

/// What one database engine brings to the queue.
#[async_trait::async_trait]
pub(super) trait Backend: Send + Sync + std::fmt::Debug + 'static {
    /// A connection.
    type Conn: Conn;
    /// A write transaction (holding whatever turn the engine needs).
    type Tx: DerefMut<Target = Self::Conn> + Send;
    /// A connection for reads.
    type Read: DerefMut<Target = Self::Conn> + Send;

    /// The clock, in milliseconds since the epoch.
    const NOW: &'static str;
    /// The comma-separated graph indices of the dependencies of `jobs`,
    /// in order.
    const DEPS: &'static str;
    /// Locks the rows a `SELECT` reads until the transaction ends.
    const FOR_UPDATE: &'static str;
    /// Locks the rows a `SELECT` reads, skipping those locked by others.
    const SKIP_LOCKED: &'static str;

    /// Starts a write transaction.
    async fn begin(&self, durability: Durability) -> Result<Self::Tx>;
    /// Commits it.
    async fn commit(tx: Self::Tx) -> Result<()>;
    /// Rolls it back (best effort: the connection is dropped otherwise).
    async fn rollback(tx: Self::Tx);
    /// A connection for reads.
    async fn read(&self) -> Result<Self::Read>;

    /// Tells every server that jobs may have become ready, when the
    /// transaction commits; a single-server engine needs nothing.
    async fn wake(_tx: &mut Self::Conn) -> Result<()> {
        Ok(())
    }

    /// Wakes `ready` whenever another server makes jobs ready.
    async fn listen(&self, _ready: Arc<tokio::sync::Notify>) -> Result<()> {
        Ok(())
    }

    /// See [`Store::share_events`]; a single-server engine shares none.
    async fn share_events(
        &self,
        _events: tokio::sync::broadcast::Sender<crate::state::BakeEvent>,
    ) -> Result<Option<tokio::sync::mpsc::UnboundedSender<crate::state::BakeEvent>>> {
        Ok(None)
    }

    /// A statement with the dialect's placeholders expanded.
    fn sql(text: &str) -> Stmt {
        let mut sql = text.to_owned();
        // Most statements have no placeholder: nothing to replace.
        if text.contains('{') {
            for (name, value) in [
                ("{now}", Self::NOW),
                ("{deps}", Self::DEPS),
                ("{for_update}", Self::FOR_UPDATE),
                ("{skip_locked}", Self::SKIP_LOCKED),
            ] {
                sql = sql.replace(name, value);
            }
        }
        debug_assert!(!sql.contains('{'), "unexpanded placeholder in {sql}");
        Stmt {
            sql,
            args: Vec::new(),
        }
    }
}

/// Runs `$body` (an async block that may `return` early) in a write
/// transaction of `$store`'s backend, where `$tx` is the connection:
/// commits when it returns `Ok`, rolls back explicitly when it fails, so a
/// pooled connection never goes back to the pool inside a transaction.
macro_rules! in_tx {
    ($store:expr, $durability:expr, |$tx:ident| $body:block) => {{
        let mut guard = $store.backend.begin($durability).await?;
        let result: Result<_> = async {
            let $tx = &mut *guard;
            $body
        }
        .await;
        match result {
            Ok(value) => {
                B::commit(guard).await?;
                Ok(value)
            }
            Err(e) => {
                B::rollback(guard).await;
                Err(e)
            }
        }
    }};
}

/// The store over one backend.
#[derive(Debug, Clone)]
pub struct SqlStore<B> {
    pub(super) backend: B,
}

/// Jobs with their dependencies' graph indices.
const JOB_SELECT: &str = "SELECT jobs.*, {deps} AS deps FROM jobs";

/// Marks the workers' view: `worker` has no job now.
const WORKER_IDLE: &str =
    "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {now} WHERE id = $1";

/// How far bake `$1`'s unfinished jobs got (the furthest attempt of
/// each), which a view and an event add to its finished jobs' work
/// (`BakeRow::running_work`), and what its running jobs are doing again
/// (`BakeRow::redo_work`).
const RUNNING_WORK: &str = "SELECT CAST(COALESCE(SUM(r.reached), 0) AS BIGINT) FROM jobs r WHERE r.bake_id = $1 AND r.state != 'completed'";
const REDO_WORK: &str = "SELECT CAST(COALESCE(SUM(r.reached - r.progress), 0) AS BIGINT) FROM jobs r WHERE r.bake_id = $1 AND r.state = 'running' AND r.reached > r.progress";

/// A bake's columns with [`RUNNING_WORK`] and [`REDO_WORK`], read in one
/// statement (one snapshot: a completion cannot fall between the
/// numbers).
fn bake_columns() -> &'static str {
    static COLUMNS: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
        format!(
            "bakes.*, ({}) AS running_work, ({}) AS redo_work",
            RUNNING_WORK.replace("$1", "bakes.id"),
            REDO_WORK.replace("$1", "bakes.id")
        )
    });
    &COLUMNS
}

async fn bake_by_id<B: Backend>(c: &mut B::Conn, id: i64, lock: bool) -> Result<BakeRow> {
    let bake = if lock {
        // The lock is on the row alone; the jobs' progress is read after,
        // under it.
        let row = c
            .optional::<RawBake>(B::sql("SELECT * FROM bakes WHERE id = $1{for_update}").bind(id))
            .await?;
        match row {
            Some(row) => Some(with_running_work::<B>(c, row.cook()?).await?),
            None => None,
        }
    } else {
        c.optional::<RawBake>(
            B::sql(&format!(
                "SELECT {} FROM bakes WHERE id = $1",
                bake_columns()
            ))
            .bind(id),
        )
        .await?
        .map(RawBake::cook)
        .transpose()?
    };
    bake.ok_or_else(|| StoreError::NotFound(format!("bake {id}")))
}

/// `bake` with its unfinished jobs' progress, for a row read or written
/// without it (a locked read, `RETURNING`).
async fn with_running_work<B: Backend>(c: &mut B::Conn, mut bake: BakeRow) -> Result<BakeRow> {
    let (running, redo): (i64, i64) = c
        .one(B::sql(&format!("SELECT ({RUNNING_WORK}), ({REDO_WORK})")).bind(bake.id))
        .await?;
    bake.running_work = running;
    bake.redo_work = redo;
    Ok(bake)
}

async fn job_by_id<B: Backend>(c: &mut B::Conn, id: i64) -> Result<JobRow> {
    c.optional::<RawJob>(B::sql(&format!("{JOB_SELECT} WHERE jobs.id = $1")).bind(id))
        .await?
        .ok_or_else(|| StoreError::NotFound(format!("job {id}")))?
        .cook()
}

/// The job, locked, if `token` is its current lease, else `LeaseLost`.
async fn leased<B: Backend>(c: &mut B::Conn, job: i64, token: &str) -> Result<JobRow> {
    let held: Option<i64> = c
        .scalar(
            B::sql("SELECT id FROM jobs WHERE id = $1 AND lease_token = $2 AND state = 'running'{for_update}")
                .bind(job)
                .bind(token),
        )
        .await?;
    if held.is_none() {
        return Err(StoreError::LeaseLost(format!(
            "job {job} is not leased with this token"
        )));
    }
    job_by_id::<B>(c, job).await
}

/// After `jobs` completed: each dependent has as many dependencies fewer
/// as it had among them, and those with none left become available.
/// Touches only the jobs' direct dependents, so a completion costs the
/// same however large the bake.
async fn release_dependents<B: Backend>(c: &mut B::Conn, jobs: &[i64]) -> Result<()> {
    if jobs.is_empty() {
        return Ok(());
    }
    // Every placeholder list is the same `jobs`; SET sees the row before
    // this update.
    let list = placeholders(1, jobs.len());
    c.execute(
        B::sql(&format!("UPDATE jobs SET pending_deps = pending_deps - (SELECT COUNT(*) FROM job_deps d WHERE d.job_id = jobs.id AND d.dep_id IN ({list})), state = CASE WHEN state = 'blocked' AND pending_deps = (SELECT COUNT(*) FROM job_deps d WHERE d.job_id = jobs.id AND d.dep_id IN ({list})) THEN 'available' ELSE state END WHERE id IN (SELECT job_id FROM job_deps WHERE dep_id IN ({list}))"))
            .bind_all(jobs.iter().copied()),
    )
    .await?;
    Ok(())
}

/// Locks the rows of `workers` in id order, the order every transaction
/// that takes several of them keeps (`lease_batch`, a stop, a poll), so
/// none waits on another in a cycle; returns the ids of those stopped.
async fn lock_workers<'a, B: Backend>(
    c: &mut B::Conn,
    workers: impl ExactSizeIterator<Item = &'a str>,
) -> Result<Vec<String>> {
    let n = workers.len();
    let rows: Vec<(String, String)> = c
        .all(
            B::sql(&format!(
                "SELECT id, state FROM workers WHERE id IN ({}) ORDER BY id{{for_update}}",
                placeholders(1, n)
            ))
            .bind_all(workers),
        )
        .await?;
    Ok(rows
        .into_iter()
        .filter(|(_, state)| state == "stopped")
        .map(|(id, _)| id)
        .collect())
}

/// Locks the slots' rows in id order, as a lease takes them, where the
/// store locks rows (PostgreSQL); SQLite runs one writing transaction at a
/// time, so there it asks nothing (a poll's every wake would otherwise
/// read the rows for no lock).
async fn lock_worker_rows<'a, B: Backend>(
    c: &mut B::Conn,
    workers: impl ExactSizeIterator<Item = &'a str>,
) -> Result<()> {
    if B::FOR_UPDATE.is_empty() {
        return Ok(());
    }
    lock_workers::<B>(c, workers).await.map(drop)
}

/// Recounts the pending dependencies of the bake's blocked jobs and makes
/// those with none available (after a retry re-blocks jobs).
async fn unblock<B: Backend>(c: &mut B::Conn, bake: i64) -> Result<()> {
    c.execute(
        B::sql("UPDATE jobs SET pending_deps = (SELECT COUNT(*) FROM job_deps d JOIN jobs p ON p.id = d.dep_id WHERE d.job_id = jobs.id AND p.state != 'completed') WHERE bake_id = $1 AND state = 'blocked'")
            .bind(bake),
    )
    .await?;
    c.execute(
        B::sql("UPDATE jobs SET state = 'available' WHERE bake_id = $1 AND state = 'blocked' AND pending_deps = 0")
            .bind(bake),
    )
    .await?;
    Ok(())
}

/// Marks the bake failed when one of its jobs is dead.
async fn fail_bake_if_dead<B: Backend>(c: &mut B::Conn, bake: i64) -> Result<()> {
    c.execute(
        B::sql("UPDATE bakes SET state = 'failed', updated_at = {now}, finished_at = {now}, error = (SELECT 'job ' || id || ' (' || kind || ', #' || idx || ' of the bake) died after ' || attempts || CASE WHEN attempts = 1 THEN ' attempt' ELSE ' attempts' END || COALESCE(' on ' || worker, '') || ': ' || COALESCE(error, 'lease expired') FROM jobs WHERE bake_id = bakes.id AND state = 'dead' ORDER BY idx LIMIT 1) WHERE id = $1 AND state IN ('queued', 'running', 'paused') AND EXISTS (SELECT 1 FROM jobs WHERE bake_id = bakes.id AND state = 'dead')")
            .bind(bake),
    )
    .await?;
    Ok(())
}

/// How recently (ms) an idle GPU worker must have polled to count as
/// waiting: a waiting worker polls again at least every second
/// (`routes::jobs`'s long poll), so two seconds miss none.
const GPU_WAITING_MS: u32 = 2000;

/// Claims up to `limit` ready jobs, in order, from the most urgent bakes
/// this worker is not kept off: index lookups, however many jobs are
/// queued. Claimers on other connections skip the rows each other locked.
///
/// Tracing jobs prefer GPU workers: a CPU worker passes over them while a
/// GPU worker that may take the bake is waiting for a job (idle, and
/// polling within the last two seconds), which then claims them at once.
/// A fleet without an idle GPU worker is never held up: busy or silent
/// GPU workers are not waited for.
async fn claim<B: Backend>(
    c: &mut B::Conn,
    worker: &str,
    policy: &QueuePolicy,
    limit: usize,
    taken: &[i64],
) -> Result<Vec<i64>> {
    let bakes: Vec<(i64,)> = c
        .all(
            B::sql("SELECT b.id FROM bakes b WHERE b.state IN ('queued', 'running') AND EXISTS (SELECT 1 FROM jobs j WHERE j.bake_id = b.id AND j.state = 'available') AND NOT EXISTS (SELECT 1 FROM worker_failures f WHERE f.bake_id = b.id AND f.worker = $1 AND f.failures >= $2 AND EXISTS (SELECT 1 FROM workers o WHERE o.id != $1 AND o.state != 'stopped' AND o.last_seen > {now} - 60000 AND NOT EXISTS (SELECT 1 FROM worker_failures g WHERE g.bake_id = b.id AND g.worker = o.id AND g.failures >= $2))) ORDER BY b.priority DESC, b.id LIMIT 8")
                .bind(worker)
                .bind(policy.worker_failures),
        )
        .await?;
    let tracing = JobSpec::TRACING_KINDS.map(|k| format!("'{k}'")).join(", ");
    let mut ids = Vec::new();
    // Jobs this transaction claimed for other slots are still `available`
    // to it (its own row locks do not skip them): leave them out.
    let taken_clause = if taken.is_empty() {
        String::new()
    } else {
        format!(" AND id NOT IN ({})", placeholders(5, taken.len()))
    };
    for (bake,) in bakes {
        let more: Vec<(i64,)> = c
            .all(
                B::sql(&format!("SELECT id FROM jobs WHERE bake_id = $1 AND state = 'available' AND NOT (kind IN ({tracing}) AND EXISTS (SELECT 1 FROM workers me WHERE me.id = $2 AND me.tracer = 'cpu') AND EXISTS (SELECT 1 FROM workers g WHERE g.id != $2 AND g.tracer LIKE 'gpu%' AND g.state = 'idle' AND g.last_seen > {{now}} - {GPU_WAITING_MS} AND NOT EXISTS (SELECT 1 FROM worker_failures f WHERE f.bake_id = $1 AND f.worker = g.id AND f.failures >= $3))){taken_clause} ORDER BY idx LIMIT $4{{skip_locked}}"))
                    .bind(bake)
                    .bind(worker)
                    .bind(policy.worker_failures)
                    .bind(i64::try_from(limit - ids.len()).unwrap_or(i64::MAX))
                    .bind_all(taken.iter().copied()),
            )
            .await?;
        ids.extend(more.into_iter().map(|(id,)| id));
        if ids.len() >= limit {
            break;
        }
    }
    Ok(ids)
}

/// Splits a batch's workers into those that would claim alike: workers
/// with no failures to be kept off for and the same tracer see the same
/// jobs, so one claim serves them all; a worker with failures claims on
/// its own. Groups hold indices into `workers`, in its order.
async fn claim_groups<B: Backend>(
    c: &mut B::Conn,
    workers: &[String],
    policy: &QueuePolicy,
) -> Result<Vec<Vec<usize>>> {
    match workers.len() {
        0 => return Ok(Vec::new()),
        1 => return Ok(vec![vec![0]]),
        _ => {}
    }
    let known: Vec<(String, Option<String>)> = c
        .all(
            B::sql(&format!(
                "SELECT id, tracer FROM workers WHERE id IN ({})",
                placeholders(1, workers.len())
            ))
            .bind_all(workers),
        )
        .await?;
    let failing: Vec<(String,)> = c
        .all(
            B::sql(&format!(
                "SELECT DISTINCT worker FROM worker_failures WHERE failures >= $1 AND worker IN ({})",
                placeholders(2, workers.len())
            ))
            .bind(policy.worker_failures)
            .bind_all(workers),
        )
        .await?;
    let tracer: HashMap<&str, Option<&str>> = known
        .iter()
        .map(|(id, t)| (id.as_str(), t.as_deref()))
        .collect();
    let failing: BTreeSet<&str> = failing.iter().map(|(w,)| w.as_str()).collect();
    let mut groups: Vec<(Option<Option<&str>>, Vec<usize>)> = Vec::new();
    for (i, w) in workers.iter().enumerate() {
        // `None`: a group of its own.
        let key =
            (!failing.contains(w.as_str())).then(|| tracer.get(w.as_str()).copied().flatten());
        match groups.iter_mut().find(|(k, _)| key.is_some() && *k == key) {
            Some((_, group)) => group.push(i),
            None => groups.push((key, vec![i])),
        }
    }
    Ok(groups.into_iter().map(|(_, g)| g).collect())
}

/// What a leased job reads: the outputs of its dependencies, in graph
/// order, and its bake's uploads.
async fn lease_inputs<B: Backend>(c: &mut B::Conn, job: &JobRow) -> Result<Vec<Completion>> {
    let mut inputs = Vec::new();
    if !job.deps.is_empty() {
        let deps: Vec<(Option<String>, Option<String>)> = c
            .all(
                B::sql("SELECT p.outputs, p.timings FROM job_deps d JOIN jobs p ON p.id = d.dep_id WHERE d.job_id = $1 ORDER BY p.idx")
                    .bind(job.id),
            )
            .await?;
        for (outputs, timings) in deps {
            inputs.push(Completion {
                outputs: serde_json::from_str(outputs.as_deref().unwrap_or("[]"))?,
                timings: serde_json::from_str(timings.as_deref().unwrap_or("null"))?,
            });
        }
    }
    Ok(inputs)
}

/// The uploads a bake's jobs read: whether each is a bundle, character
/// first.
async fn bake_uploads<B: Backend>(c: &mut B::Conn, bake: &BakeRow) -> Result<Vec<UploadRef>> {
    let mut uploads = Vec::new();
    for digest in std::iter::once(&bake.character).chain(&bake.clips) {
        let bundle: Option<bool> = c
            .scalar(B::sql("SELECT bundle FROM uploads WHERE digest = $1 LIMIT 1").bind(digest))
            .await?;
        uploads.push(UploadRef {
            digest: digest.clone(),
            bundle: bundle.unwrap_or(false),
        });
    }
    Ok(uploads)
}

/// What a batch of completions adds to one bake.
#[derive(Debug, Default)]
struct BakeCounts {
    work: i64,
    jobs: i64,
    asset: Option<String>,
    report: Option<String>,
    plot: Option<String>,
}

impl BakeCounts {
    fn add(&mut self, work: i64, done: &Completion) {
        self.work += work;
        self.jobs += 1;
        for o in &done.outputs {
            let slot = match o.name.as_str() {
                "asset" => &mut self.asset,
                "report.json" => &mut self.report,
                "plot.png" => &mut self.plot,
                _ => continue,
            };
            slot.get_or_insert_with(|| o.digest.clone());
        }
    }
}

/// Applies a control to a bake whose row the transaction holds.
async fn apply<B: Backend>(c: &mut B::Conn, b: &BakeRow, action: Action) -> Result<()> {
    let bake = b.id;
    let refuse = |why: &str| {
        Err(StoreError::Conflict(format!(
            "bake {bake} is {}: {why}",
            b.state.as_str()
        )))
    };
    match action {
        Action::Cancel => {
            if !b.state.is_active() {
                return refuse("only a queued, running or paused bake can be cancelled");
            }
            c.execute(
                B::sql("UPDATE jobs SET state = 'cancelled', lease_token = NULL, lease_expires_at = NULL WHERE bake_id = $1 AND state NOT IN ('completed', 'dead')")
                    .bind(bake),
            )
            .await?;
            c.execute(
                B::sql("UPDATE bakes SET state = 'cancelled', finished_at = {now}, updated_at = {now} WHERE id = $1")
                    .bind(bake),
            )
            .await?;
        }
        Action::Pause => {
            if !matches!(b.state, BakeState::Queued | BakeState::Running) {
                return refuse("only a queued or running bake can be paused");
            }
            c.execute(
                B::sql("UPDATE bakes SET state = 'paused', updated_at = {now} WHERE id = $1")
                    .bind(bake),
            )
            .await?;
        }
        Action::Resume => {
            if b.state != BakeState::Paused {
                return refuse("only a paused bake can be resumed");
            }
            c.execute(
                B::sql("UPDATE bakes SET state = CASE WHEN jobs_done > 0 OR EXISTS (SELECT 1 FROM jobs WHERE bake_id = bakes.id AND state = 'running') THEN 'running' ELSE 'queued' END, updated_at = {now} WHERE id = $1")
                    .bind(bake),
            )
            .await?;
        }
        Action::Retry => requeue::<B>(c, b, &[]).await?,
    }
    Ok(())
}

/// Queues bake `b` (its row held) again: its unfinished jobs with fresh
/// attempts, and its completed jobs `lost` (whose outputs the blob store
/// lost) run again, their outputs forgotten and their work counted as
/// reached, so the bake's progress does not move back. A failed or
/// cancelled bake, or a done one with jobs to run again.
async fn requeue<B: Backend>(c: &mut B::Conn, b: &BakeRow, lost: &[i64]) -> Result<()> {
    let bake = b.id;
    let retryable = matches!(b.state, BakeState::Failed | BakeState::Cancelled)
        || (b.state == BakeState::Done && !lost.is_empty());
    if !retryable {
        return Err(StoreError::Conflict(format!(
            "bake {bake} is {}: only a failed or cancelled bake can be retried, or a done one whose outputs the blob store lost",
            b.state.as_str()
        )));
    }
    let (mut work, mut jobs) = (0i64, 0i64);
    // What the bake publishes from a job run again is forgotten with it
    // (the run publishes it again).
    let mut forgotten: BTreeSet<String> = BTreeSet::new();
    for &job in lost {
        let row: Option<(i64, Option<String>)> = c
            .optional(
                B::sql("SELECT work, outputs FROM jobs WHERE id = $1 AND bake_id = $2 AND state = 'completed'")
                    .bind(job)
                    .bind(bake),
            )
            .await?;
        let Some((w, outputs)) = row else { continue };
        let outputs: Vec<super::OutputRef> =
            serde_json::from_str(outputs.as_deref().unwrap_or("[]"))?;
        forgotten.extend(outputs.into_iter().map(|o| o.digest));
        c.execute(
            B::sql("UPDATE jobs SET state = 'blocked', attempts = 0, error = NULL, run_at = 0, progress = 0, reached = work, outputs = NULL, finished_at = NULL, lease_token = NULL, lease_expires_at = NULL WHERE id = $1")
                .bind(job),
        )
        .await?;
        work += w;
        jobs += 1;
    }
    if b.state == BakeState::Done && jobs == 0 {
        // (None of them completed: nothing would run, and the bake would
        // stay queued.)
        return Err(StoreError::Conflict(format!(
            "bake {bake} is done and none of the jobs named is a completed job of it: nothing to run again"
        )));
    }
    let keep = |d: &Option<String>| d.clone().filter(|d| !forgotten.contains(d));
    // Jobs still running in a failed or cancelled bake are taken back
    // too (their workers' next heartbeat hears the lease is gone): one
    // may read an output run again, or be on its last attempt.
    c.execute(
        B::sql("UPDATE jobs SET state = 'blocked', attempts = 0, error = NULL, run_at = 0, lease_token = NULL, lease_expires_at = NULL WHERE bake_id = $1 AND state IN ('dead', 'cancelled', 'retryable', 'available', 'running')")
            .bind(bake),
    )
    .await?;
    c.execute(B::sql("DELETE FROM worker_failures WHERE bake_id = $1").bind(bake))
        .await?;
    unblock::<B>(c, bake).await?;
    c.execute(
        B::sql("UPDATE bakes SET state = 'queued', error = NULL, finished_at = NULL, done_work = done_work - $2, jobs_done = jobs_done - $3, asset = $4, report = $5, plot = $6, updated_at = {now} WHERE id = $1")
            .bind(bake)
            .bind(work)
            .bind(jobs)
            .bind(keep(&b.asset))
            .bind(keep(&b.report))
            .bind(keep(&b.plot)),
    )
    .await?;
    Ok(())
}

#[async_trait::async_trait]
impl<B: Backend> Store for SqlStore<B> {
    async fn put_upload(&self, u: &UploadRow) -> Result<bool> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let done = c
                .execute(
                    B::sql("INSERT INTO uploads (digest, kind, bundle, bytes, summary, created_at) VALUES ($1, $2, $3, $4, $5, {now}) ON CONFLICT (digest, kind) DO NOTHING")
                        .bind(&u.digest)
                        .bind(&u.kind)
                        .bind(u.bundle)
                        .bind(u.bytes)
                        .bind(u.summary.to_string()),
                )
                .await?;
            Ok(done == 1)
        })
    }

    async fn uploads(&self) -> Result<Vec<UploadRow>> {
        let rows: Vec<RawUpload> = self
            .backend
            .read()
            .await?
            .all(B::sql("SELECT * FROM uploads ORDER BY created_at, digest"))
            .await?;
        rows.into_iter().map(RawUpload::cook).collect()
    }

    async fn forget_checkpoint(&self, job: i64, blob: &str) -> Result<()> {
        in_tx!(self, Durability::Acknowledged, |c| {
            c.execute(
                B::sql("UPDATE jobs SET checkpoint_step = NULL, checkpoint_cursor = NULL, checkpoint_blob = NULL WHERE id = $1 AND state != 'completed' AND checkpoint_blob = $2")
                    .bind(job)
                    .bind(blob),
            )
            .await?;
            Ok(())
        })
    }

    async fn upload(&self, digest: &str, kind: &str) -> Result<Option<UploadRow>> {
        let row: Option<RawUpload> = self
            .backend
            .read()
            .await?
            .optional(
                B::sql("SELECT * FROM uploads WHERE digest = $1 AND kind = $2")
                    .bind(digest)
                    .bind(kind),
            )
            .await?;
        row.map(RawUpload::cook).transpose()
    }

    async fn create_bake(&self, b: &NewBake) -> Result<BakeRow> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let total: i64 = b.jobs.iter().map(|j| j.work).sum();
            let (id,): (i64,) = c
                .one(
                    B::sql("INSERT INTO bakes (key, character, clips, method, params, state, priority, total_work, jobs_total, created_at, updated_at) VALUES ($1, $2, $3, $4, $5, 'queued', $6, $7, $8, {now}, {now}) RETURNING id")
                        .bind(&b.key)
                        .bind(&b.character)
                        .bind(serde_json::to_string(&b.clips)?)
                        .bind(&b.method)
                        .bind(b.params.to_string())
                        .bind(b.priority)
                        .bind(total)
                        .bind(b.jobs.len() as i64),
                )
                .await?;
            let mut ids = Vec::with_capacity(b.jobs.len());
            for (i, j) in b.jobs.iter().enumerate() {
                let state = if j.deps.is_empty() {
                    "available"
                } else {
                    "blocked"
                };
                let (job,): (i64,) = c
                    .one(
                        B::sql("INSERT INTO jobs (bake_id, idx, kind, spec, work, state, max_attempts, pending_deps) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id")
                            .bind(id)
                            .bind(i as i64)
                            .bind(&j.kind)
                            .bind(j.spec.to_string())
                            .bind(j.work)
                            .bind(state)
                            .bind(b.max_attempts)
                            .bind(j.deps.len() as i64),
                    )
                    .await?;
                for &d in &j.deps {
                    let dep = *ids.get(d).ok_or_else(|| {
                        StoreError::Conflict(format!("job {i} depends on a later job {d}"))
                    })?;
                    c.execute(
                        B::sql(
                            "INSERT INTO job_deps (job_id, dep_id, dep_idx) VALUES ($1, $2, $3)",
                        )
                        .bind(job)
                        .bind(dep)
                        .bind(d as i64),
                    )
                    .await?;
                }
                ids.push(job);
            }
            B::wake(c).await?;
            bake_by_id::<B>(c, id, false).await
        })
    }

    async fn bake(&self, id: i64) -> Result<Option<BakeRow>> {
        let row: Option<RawBake> = self
            .backend
            .read()
            .await?
            .optional(
                B::sql(&format!(
                    "SELECT {} FROM bakes WHERE id = $1",
                    bake_columns()
                ))
                .bind(id),
            )
            .await?;
        row.map(RawBake::cook).transpose()
    }

    async fn bakes_for_key(&self, key: &str) -> Result<Vec<BakeRow>> {
        let rows: Vec<RawBake> = self
            .backend
            .read()
            .await?
            .all(
                B::sql(&format!("SELECT {} FROM bakes WHERE key = $1 AND state IN ('done', 'queued', 'running', 'paused') ORDER BY state = 'done' DESC, id DESC LIMIT 16", bake_columns()))
                    .bind(key),
            )
            .await?;
        rows.into_iter().map(RawBake::cook).collect()
    }

    async fn bakes(
        &self,
        character: Option<&str>,
        method: Option<&str>,
        limit: i64,
    ) -> Result<Vec<BakeRow>> {
        let rows: Vec<RawBake> = self
            .backend
            .read()
            .await?
            .all(
                B::sql(&format!("SELECT {} FROM bakes WHERE (CAST($1 AS TEXT) IS NULL OR character = $1) AND (CAST($2 AS TEXT) IS NULL OR method = $2) ORDER BY id DESC LIMIT $3", bake_columns()))
                    .bind(character)
                    .bind(method)
                    .bind(limit),
            )
            .await?;
        rows.into_iter().map(RawBake::cook).collect()
    }

    async fn jobs(&self, bake: i64) -> Result<Vec<JobRow>> {
        let rows: Vec<RawJob> = self
            .backend
            .read()
            .await?
            .all(
                B::sql(&format!(
                    "{JOB_SELECT} WHERE jobs.bake_id = $1 ORDER BY jobs.idx"
                ))
                .bind(bake),
            )
            .await?;
        rows.into_iter().map(RawJob::cook).collect()
    }

    async fn lease_batch(
        &self,
        workers: &[String],
        request: Option<&str>,
        policy: &QueuePolicy,
    ) -> Result<Vec<Lease>> {
        in_tx!(self, Durability::Queue, |c| {
            // Retries whose delay has passed are ready again.
            c.execute(B::sql(
                "UPDATE jobs SET state = 'available' WHERE state = 'retryable' AND run_at <= {now}",
            ))
            .await?;
            if workers.iter().collect::<BTreeSet<_>>().len() != workers.len() {
                return Err(StoreError::Conflict(
                    "a batch of leases names a worker twice".into(),
                ));
            }
            // A slot whose process said it stopped gets no job: the poll
            // asking for it is abandoned. The slots' rows are locked first
            // (before any job's, the order `workers_stopped` takes too), so
            // a stop either commits before this and is seen here, or waits
            // and then gives back what this leased.
            let stopped = lock_workers::<B>(c, workers.iter().map(String::as_str)).await?;
            let live: Vec<String>;
            let workers = if stopped.is_empty() {
                workers
            } else {
                live = workers
                    .iter()
                    .filter(|w| !stopped.contains(w))
                    .cloned()
                    .collect();
                if live.is_empty() {
                    return Ok(Vec::new());
                }
                &live[..]
            };
            // The same request sent again (its answer was lost: a server
            // that died after committing it, a dropped connection) gets
            // what it leased, with the same lease and attempt, instead of
            // the jobs waiting out their leases to run a second time. Only
            // the request's own jobs (another process under the same id
            // sends other nonces), of a bake still under way, not locked
            // by another transaction (the reaper's).
            let held: Vec<(i64, String, String)> = match request {
                Some(request) => {
                    c.all(
                        B::sql(&format!(
                            "SELECT id, worker, lease_token FROM jobs WHERE state = 'running' AND lease_request = $1 AND worker IN ({}) AND EXISTS (SELECT 1 FROM bakes b WHERE b.id = jobs.bake_id AND b.state IN ('queued', 'running', 'paused')) ORDER BY id{{skip_locked}}",
                            placeholders(2, workers.len())
                        ))
                        .bind(request)
                        .bind_all(workers.iter().map(String::as_str)),
                    )
                    .await?
                }
                None => Vec::new(),
            };
            let mut grants: Vec<(usize, i64, Option<String>)> = Vec::new();
            for (id, worker, token) in held {
                let slot = workers.iter().position(|w| *w == worker);
                if let Some(slot) = slot.filter(|s| !grants.iter().any(|g| g.0 == *s)) {
                    grants.push((slot, id, Some(token)));
                }
            }
            let asking: Vec<usize> = (0..workers.len())
                .filter(|s| !grants.iter().any(|g| g.0 == *s))
                .collect();
            let names: Vec<String> = asking.iter().map(|&s| workers[s].clone()).collect();
            let mut claimed: Vec<(usize, i64)> = Vec::new();
            for group in claim_groups::<B>(c, &names, policy).await? {
                let taken: Vec<i64> = claimed.iter().map(|&(_, id)| id).collect();
                let ids = claim::<B>(c, &names[group[0]], policy, group.len(), &taken).await?;
                claimed.extend(group.into_iter().map(|g| asking[g]).zip(ids));
            }
            grants.extend(claimed.into_iter().map(|(slot, id)| (slot, id, None)));
            // In the batch's order: the first slot asked leases first.
            grants.sort_unstable();
            let mut leases = Vec::new();
            // A batch's jobs mostly share a bake: each bake is advanced
            // and its uploads looked up once.
            let mut bakes: HashMap<i64, (BakeRow, Vec<UploadRef>)> = HashMap::new();
            for (slot, id, again) in grants {
                let worker = &workers[slot];
                let granted = match again {
                    Some(token) => c
                        .optional::<RawJob>(
                            B::sql("UPDATE jobs SET lease_expires_at = {now} + $1 WHERE id = $2 AND state = 'running' RETURNING *, {deps} AS deps")
                                .bind(policy.lease_ms)
                                .bind(id),
                        )
                        .await?
                        .map(|job| (job, token)),
                    None => {
                        let token = lease_token();
                        c.optional::<RawJob>(
                            B::sql("UPDATE jobs SET state = 'running', lease_token = $1, worker = $2, attempts = attempts + 1, lease_expires_at = {now} + $3, started_at = {now}, progress = 0, lease_request = $4 WHERE id = $5 AND state = 'available' RETURNING *, {deps} AS deps")
                                .bind(&token)
                                .bind(worker)
                                .bind(policy.lease_ms)
                                .bind(request)
                                .bind(id),
                        )
                        .await?
                        .map(|job| (job, token))
                    }
                };
                // Claimed twice in one batch: never, by `taken`; a held
                // job is locked.
                let Some((job, token)) = granted else {
                    continue;
                };
                let expires_at = job.lease_expires_at.unwrap_or_default();
                let job = job.cook()?;
                if let std::collections::hash_map::Entry::Vacant(e) = bakes.entry(job.bake_id) {
                    // Only a queued bake's row is written (it starts
                    // running): a running one's is read without its lock,
                    // which completions hold while they count.
                    let started = c
                        .optional::<RawBake>(
                            B::sql("UPDATE bakes SET state = 'running', updated_at = {now} WHERE id = $1 AND state = 'queued' RETURNING *")
                                .bind(job.bake_id),
                        )
                        .await?;
                    let bake = match started {
                        // A queued bake may have reached work already (a
                        // retry keeps what its jobs had reached).
                        Some(row) => with_running_work::<B>(c, row.cook()?).await?,
                        None => bake_by_id::<B>(c, job.bake_id, false).await?,
                    };
                    let uploads = bake_uploads::<B>(c, &bake).await?;
                    e.insert((bake, uploads));
                }
                let (bake, uploads) = &bakes[&job.bake_id];
                let inputs = lease_inputs::<B>(c, &job).await?;
                leases.push(Lease {
                    job,
                    token,
                    expires_at,
                    bake: bake.clone(),
                    inputs,
                    uploads: uploads.clone(),
                });
            }
            if !leases.is_empty() {
                let rows = (0..leases.len())
                    .map(|i| format!("(${}, 'busy', ${}, {{now}}, {{now}})", 2 * i + 1, 2 * i + 2))
                    .collect::<Vec<_>>()
                    .join(", ");
                let mut upsert = B::sql(&format!(
                    "INSERT INTO workers (id, state, job_id, last_seen, started_at) VALUES {rows} ON CONFLICT (id) DO UPDATE SET state = 'busy', job_id = excluded.job_id, last_seen = excluded.last_seen"
                ));
                for l in &leases {
                    upsert = upsert.bind(l.job.worker.clone()).bind(l.job.id);
                }
                c.execute(upsert).await?;
            }
            Ok(leases)
        })
    }

    async fn heartbeat(
        &self,
        job: i64,
        token: &str,
        progress: i64,
        policy: &QueuePolicy,
    ) -> Result<Beat> {
        in_tx!(self, Durability::Queue, |c| {
            let j = leased::<B>(c, job, token).await?;
            let progress = progress.clamp(0, j.work);
            c.execute(
                B::sql(
                    "UPDATE jobs SET lease_expires_at = {now} + $1, progress = $2, reached = $3 WHERE id = $4",
                )
                .bind(policy.lease_ms)
                .bind(progress)
                .bind(progress.max(j.reached))
                .bind(job),
            )
            .await?;
            let bake = bake_by_id::<B>(c, j.bake_id, false).await?;
            c.execute(
                B::sql("UPDATE workers SET last_seen = {now}, state = 'busy', job_id = $1 WHERE id = $2")
                    .bind(job)
                    .bind(j.worker.as_deref().unwrap_or("")),
            )
            .await?;
            Ok(Beat {
                stop: !bake.state.is_active(),
                moved: progress != j.progress,
                bake,
            })
        })
    }

    async fn checkpoint(&self, job: i64, token: &str, cp: &CheckpointRef) -> Result<()> {
        in_tx!(self, Durability::Queue, |c| {
            leased::<B>(c, job, token).await?;
            c.execute(
                B::sql("UPDATE jobs SET checkpoint_step = $1, checkpoint_cursor = $2, checkpoint_blob = $3 WHERE id = $4")
                    .bind(&cp.step)
                    .bind(cp.cursor)
                    .bind(&cp.blob)
                    .bind(job),
            )
            .await?;
            Ok(())
        })
    }

    async fn complete_many(&self, items: &[JobCompletion]) -> Result<Vec<Result<BakeRow>>> {
        in_tx!(self, Durability::Acknowledged, |c| {
            // A statement per job: its completion (only with the current
            // lease token); per bake, its counts (publishing the asset,
            // report and plot when a job produced them); then one for
            // the dependents, one for the workers, one wake.
            // Per item: the job, its bake, and whether it completed now
            // (not a completion sent again).
            let mut done: Vec<Result<(i64, i64, bool)>> = Vec::with_capacity(items.len());
            // Per bake: work and jobs done, and the outputs it publishes.
            let mut counts: BTreeMap<i64, BakeCounts> = BTreeMap::new();
            let mut idle: BTreeSet<String> = BTreeSet::new();
            for item in items {
                // The token stays on the completed job: it recognises the
                // same completion sent again.
                let row: Option<(i64, i64, Option<String>)> = c
                    .optional(
                        B::sql("UPDATE jobs SET state = 'completed', lease_expires_at = NULL, progress = work, reached = work, outputs = $1, timings = $2, error = NULL, finished_at = {now} WHERE id = $3 AND lease_token = $4 AND state = 'running' RETURNING bake_id, work, worker")
                            .bind(serde_json::to_string(&item.completion.outputs)?)
                            .bind(item.completion.timings.to_string())
                            .bind(item.job)
                            .bind(&item.token),
                    )
                    .await?;
                let Some((bake_id, work, worker)) = row else {
                    // A completion whose answer was lost (a server that
                    // died after committing it, a dropped connection) and
                    // that the worker sends again, here or to another
                    // server: done already, counted once.
                    let again: Option<i64> = c
                        .scalar(
                            B::sql("SELECT bake_id FROM jobs WHERE id = $1 AND lease_token = $2 AND state = 'completed'")
                                .bind(item.job)
                                .bind(&item.token),
                        )
                        .await?;
                    done.push(match again {
                        Some(bake_id) => Ok((item.job, bake_id, false)),
                        None => Err(StoreError::LeaseLost(format!(
                            "job {} is not leased with this token",
                            item.job
                        ))),
                    });
                    continue;
                };
                counts
                    .entry(bake_id)
                    .or_default()
                    .add(work, &item.completion);
                idle.extend(worker);
                done.push(Ok((item.job, bake_id, true)));
            }
            // Those completed now, not those sent again.
            let completed: Vec<i64> = done
                .iter()
                .flatten()
                .filter(|&&(_, _, now)| now)
                .map(|&(job, _, _)| job)
                .collect();
            let mut bakes = HashMap::new();
            for (bake_id, n) in counts {
                let bake = c
                    .one::<RawBake>(
                        B::sql("UPDATE bakes SET done_work = done_work + $1, jobs_done = jobs_done + $2, updated_at = {now}, state = CASE WHEN jobs_done + $2 = jobs_total THEN 'done' ELSE state END, asset = COALESCE($3, asset), report = COALESCE($4, report), plot = COALESCE($5, plot), finished_at = CASE WHEN jobs_done + $2 = jobs_total THEN {now} ELSE finished_at END WHERE id = $6 RETURNING *")
                            .bind(n.work)
                            .bind(n.jobs)
                            .bind(n.asset)
                            .bind(n.report)
                            .bind(n.plot)
                            .bind(bake_id),
                    )
                    .await?
                    .cook()?;
                bakes.insert(bake_id, with_running_work::<B>(c, bake).await?);
            }
            // A replay's bake as it is now (its counts moved then).
            for &(_, bake_id, _) in done.iter().flatten() {
                if let std::collections::hash_map::Entry::Vacant(e) = bakes.entry(bake_id) {
                    e.insert(bake_by_id::<B>(c, bake_id, false).await?);
                }
            }
            // After the bakes' rows, locked in id order: two batches of
            // one bake, which share dependents, take their locks in turn.
            release_dependents::<B>(c, &completed).await?;
            if !idle.is_empty() {
                c.execute(
                    B::sql(&format!(
                        "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {{now}} WHERE id IN ({})",
                        placeholders(1, idle.len())
                    ))
                    .bind_all(&idle),
                )
                .await?;
            }
            if !bakes.is_empty() {
                B::wake(c).await?;
            }
            Ok(done
                .into_iter()
                .map(|r| r.map(|(_, id, _)| bakes[&id].clone()))
                .collect())
        })
    }

    async fn fail(
        &self,
        job: i64,
        token: &str,
        error: &str,
        retryable: bool,
        policy: &QueuePolicy,
    ) -> Result<BakeRow> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let j = leased::<B>(c, job, token).await?;
            let dead = !retryable || j.attempts >= j.max_attempts;
            let (now,): (i64,) = c.one(B::sql("SELECT {now}")).await?;
            c.execute(
                B::sql("UPDATE jobs SET state = $1, lease_token = NULL, lease_expires_at = NULL, run_at = $2, error = $3 WHERE id = $4")
                    .bind(if dead { "dead" } else { "retryable" })
                    .bind(now + policy.backoff_ms(j.attempts))
                    .bind(error)
                    .bind(job),
            )
            .await?;
            let worker = j.worker.as_deref().unwrap_or("");
            c.execute(
                B::sql("INSERT INTO worker_failures (bake_id, worker, failures) VALUES ($1, $2, 1) ON CONFLICT (bake_id, worker) DO UPDATE SET failures = worker_failures.failures + 1")
                    .bind(j.bake_id)
                    .bind(worker),
            )
            .await?;
            c.execute(B::sql(WORKER_IDLE).bind(worker)).await?;
            fail_bake_if_dead::<B>(c, j.bake_id).await?;
            B::wake(c).await?;
            bake_by_id::<B>(c, j.bake_id, false).await
        })
    }

    async fn release_unless_renewed(
        &self,
        job: i64,
        token: &str,
        expires_at: Option<i64>,
    ) -> Result<()> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let j = leased::<B>(c, job, token).await?;
            let released = c
                .execute(
                    B::sql("UPDATE jobs SET state = 'available', lease_token = NULL, lease_expires_at = NULL, attempts = attempts - 1 WHERE id = $1 AND (CAST($2 AS BIGINT) IS NULL OR lease_expires_at = $2)")
                        .bind(job)
                        .bind(expires_at),
                )
                .await?;
            if released == 0 {
                // Renewed since it was granted: kept.
                return Ok(());
            }
            c.execute(B::sql(WORKER_IDLE).bind(j.worker.as_deref().unwrap_or("")))
                .await?;
            B::wake(c).await?;
            Ok(())
        })
    }

    async fn reap(&self) -> Result<u64> {
        in_tx!(self, Durability::Queue, |c| {
            // One statement decides which leases expired and frees them,
            // so a lease expiring meanwhile is either in both or in neither.
            let expired: Vec<(i64, i64)> = c
                .all(B::sql("UPDATE jobs SET state = CASE WHEN attempts >= max_attempts THEN 'dead' ELSE 'retryable' END, run_at = {now}, lease_token = NULL, lease_expires_at = NULL, error = COALESCE(error, 'lease expired') WHERE state = 'running' AND lease_expires_at < {now} RETURNING id, bake_id"))
                .await?;
            if expired.is_empty() {
                return Ok(0);
            }
            c.execute(
                B::sql("UPDATE counters SET value = value + $1 WHERE name = 'lease_expiries'")
                    .bind(expired.len() as i64),
            )
            .await?;
            for &(_, bake) in &expired {
                fail_bake_if_dead::<B>(c, bake).await?;
            }
            B::wake(c).await?;
            Ok(expired.len() as u64)
        })
    }

    async fn control(&self, bake: i64, action: Action) -> Result<BakeRow> {
        in_tx!(self, Durability::Acknowledged, |c| {
            // The bake's row is locked: its state is read, checked and
            // written back, and a completion or another control must not
            // slip in between.
            let b = bake_by_id::<B>(c, bake, true).await?;
            apply::<B>(c, &b, action).await?;
            B::wake(c).await?;
            bake_by_id::<B>(c, bake, false).await
        })
    }

    async fn retry(&self, bake: i64, lost: &[i64]) -> Result<BakeRow> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let b = bake_by_id::<B>(c, bake, true).await?;
            requeue::<B>(c, &b, lost).await?;
            B::wake(c).await?;
            bake_by_id::<B>(c, bake, false).await
        })
    }

    async fn set_priority(&self, bake: i64, priority: i64) -> Result<BakeRow> {
        in_tx!(self, Durability::Acknowledged, |c| {
            c.execute(
                B::sql("UPDATE bakes SET priority = $1, updated_at = {now} WHERE id = $2")
                    .bind(priority)
                    .bind(bake),
            )
            .await?;
            bake_by_id::<B>(c, bake, false).await
        })
    }

    async fn workers_idle(&self, workers: &[String]) -> Result<()> {
        // Once each: an upsert may not touch a row twice.
        let workers: BTreeSet<&String> = workers.iter().collect();
        if workers.is_empty() {
            return Ok(());
        }
        let rows = (1..=workers.len())
            .map(|i| format!("(${i}, 'idle', NULL, {{now}}, {{now}})"))
            .collect::<Vec<_>>()
            .join(", ");
        in_tx!(self, Durability::Queue, |c| {
            c.execute(
                B::sql(&format!("INSERT INTO workers (id, state, job_id, last_seen, started_at) VALUES {rows} ON CONFLICT (id) DO UPDATE SET state = 'idle', job_id = NULL, last_seen = excluded.last_seen"))
                    .bind_all(workers.iter().map(|w| w.as_str())),
            )
            .await?;
            Ok(())
        })
    }

    async fn workers_still_waiting(&self, workers: &[String]) -> Result<bool> {
        let workers: BTreeSet<&String> = workers.iter().collect();
        if workers.is_empty() {
            return Ok(true);
        }
        in_tx!(self, Durability::Queue, |c| {
            lock_worker_rows::<B>(c, workers.iter().map(|w| w.as_str())).await?;
            let waiting = c
                .execute(
                    B::sql(&format!(
                        "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {{now}} WHERE id IN ({}) AND state != 'stopped'",
                        placeholders(1, workers.len())
                    ))
                    .bind_all(workers.iter().map(|w| w.as_str())),
                )
                .await?;
            Ok(waiting == workers.len() as u64)
        })
    }

    async fn workers_stopped(&self, workers: &[String]) -> Result<()> {
        if workers.is_empty() {
            return Ok(());
        }
        let list = placeholders(1, workers.len());
        in_tx!(self, Durability::Queue, |c| {
            // The rows first, in id order as a lease takes them: a lease
            // of these slots under way finishes before this goes on, one
            // after sees them stopped.
            lock_worker_rows::<B>(c, workers.iter().map(String::as_str)).await?;
            c.execute(
                B::sql(&format!(
                    "UPDATE workers SET state = 'stopped', job_id = NULL WHERE id IN ({list})"
                ))
                .bind_all(workers.iter().map(String::as_str)),
            )
            .await?;
            // A job still leased to them was leased as the process went
            // (its poll's answer was never read): it is given back as a
            // release would, its attempt not counted.
            let given_back = c
                .execute(
                    B::sql(&format!(
                        "UPDATE jobs SET state = 'available', lease_token = NULL, lease_expires_at = NULL, attempts = attempts - 1 WHERE state = 'running' AND worker IN ({list})"
                    ))
                    .bind_all(workers.iter().map(String::as_str)),
                )
                .await?;
            if given_back > 0 {
                B::wake(c).await?;
            }
            Ok(())
        })
    }

    async fn forget_workers(&self, gone_ms: i64) -> Result<u64> {
        in_tx!(self, Durability::Queue, |c| {
            c.execute(
                B::sql("DELETE FROM workers WHERE last_seen < {now} - $1 AND NOT EXISTS (SELECT 1 FROM jobs j WHERE j.state = 'running' AND j.worker = workers.id)")
                    .bind(gone_ms),
            )
            .await
        })
    }

    async fn worker_tracer(&self, worker: &str, tracer: &str) -> Result<()> {
        in_tx!(self, Durability::Queue, |c| {
            c.execute(
                B::sql("INSERT INTO workers (id, state, job_id, last_seen, started_at, tracer) VALUES ($1, 'idle', NULL, {now}, {now}, $2) ON CONFLICT (id) DO UPDATE SET tracer = $2, last_seen = {now}, started_at = {now}")
                    .bind(worker)
                    .bind(tracer),
            )
            .await?;
            Ok(())
        })
    }

    async fn workers(&self, gone_after_ms: i64) -> Result<Vec<WorkerRow>> {
        let rows: Vec<RawWorker> = self
            .backend
            .read()
            .await?
            .all(
                B::sql("SELECT id, CASE WHEN gone THEN 'stopped' WHEN state = 'busy' AND holding IS NULL THEN 'idle' ELSE state END AS state, CASE WHEN gone THEN NULL ELSE holding END AS job_id, CASE WHEN gone THEN NULL ELSE holding_bake END AS bake_id, last_seen, started_at, tracer FROM (SELECT w.*, w.last_seen < {now} - $1 AS gone, j.id AS holding, j.bake_id AS holding_bake FROM workers w LEFT JOIN jobs j ON j.id = w.job_id AND j.state = 'running' AND j.worker = w.id) seen ORDER BY last_seen DESC, id")
                    .bind(gone_after_ms),
            )
            .await?;
        Ok(rows.into_iter().map(RawWorker::cook).collect())
    }

    async fn create_token_until(
        &self,
        hash: &str,
        name: &str,
        scopes: &[String],
        expires_at: Option<i64>,
    ) -> Result<()> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let revoked: Option<(i64,)> = c
                .optional(
                    B::sql("SELECT revoked_at FROM revoked_tokens WHERE hash = $1").bind(hash),
                )
                .await?;
            if let Some((at,)) = revoked {
                return Err(StoreError::Revoked(at));
            }
            c.execute(
                B::sql("INSERT INTO tokens (hash, name, scopes, created_at, expires_at) VALUES ($1, $2, $3, {now}, $4) ON CONFLICT (hash) DO UPDATE SET name = excluded.name, scopes = excluded.scopes")
                    .bind(hash)
                    .bind(name)
                    .bind(scopes.join(","))
                    .bind(expires_at),
            )
            .await?;
            Ok(())
        })
    }

    async fn token(&self, hash: &str) -> Result<Option<TokenRow>> {
        let row: Option<RawToken> = self
            .backend
            .read()
            .await?
            .optional(
                B::sql("SELECT hash, name, scopes, created_at, expires_at, last_used_at FROM tokens WHERE hash = $1 AND NOT EXISTS (SELECT 1 FROM revoked_tokens r WHERE r.hash = tokens.hash)").bind(hash),
            )
            .await?;
        Ok(row.map(|r| r.cook().1))
    }

    async fn token_used(&self, hash: &str, at: i64) -> Result<()> {
        in_tx!(self, Durability::Queue, |c| {
            c.execute(
                B::sql("UPDATE tokens SET last_used_at = $2 WHERE hash = $1 AND (last_used_at IS NULL OR last_used_at <= $2 - 60000)")
                    .bind(hash)
                    .bind(at),
            )
            .await?;
            Ok(())
        })
    }

    async fn tokens(&self) -> Result<Vec<(String, TokenRow)>> {
        let rows: Vec<RawToken> = self
            .backend
            .read()
            .await?
            .all(B::sql(
                "SELECT hash, name, scopes, created_at, expires_at, last_used_at FROM tokens WHERE NOT EXISTS (SELECT 1 FROM revoked_tokens r WHERE r.hash = tokens.hash) ORDER BY created_at DESC, hash",
            ))
            .await?;
        Ok(rows.into_iter().map(RawToken::cook).collect())
    }

    async fn delete_token(&self, hash: &str, revoke: bool) -> Result<bool> {
        in_tx!(self, Durability::Acknowledged, |c| {
            let deleted = c
                .execute(B::sql("DELETE FROM tokens WHERE hash = $1").bind(hash))
                .await?;
            if revoke && deleted > 0 {
                c.execute(
                    B::sql("INSERT INTO revoked_tokens (hash, revoked_at) VALUES ($1, {now}) ON CONFLICT (hash) DO NOTHING")
                        .bind(hash),
                )
                .await?;
            }
            Ok(deleted > 0)
        })
    }

    async fn queue_stats(&self) -> Result<(Vec<(JobState, i64)>, i64)> {
        let mut c = self.backend.read().await?;
        let rows: Vec<(String, i64)> = c
            .all(B::sql("SELECT state, COUNT(*) FROM jobs GROUP BY state"))
            .await?;
        let (expiries,): (i64,) = c
            .one(B::sql(
                "SELECT value FROM counters WHERE name = 'lease_expiries'",
            ))
            .await?;
        Ok((
            rows.into_iter()
                .map(|(s, n)| (JobState::parse(&s), n))
                .collect(),
            expiries,
        ))
    }

    async fn ping(&self) -> Result<()> {
        self.backend
            .read()
            .await?
            .execute(B::sql("SELECT 1"))
            .await?;
        Ok(())
    }

    async fn listen(&self, ready: Arc<tokio::sync::Notify>) -> Result<()> {
        self.backend.listen(ready).await
    }

    async fn share_events(
        &self,
        events: tokio::sync::broadcast::Sender<crate::state::BakeEvent>,
    ) -> Result<Option<tokio::sync::mpsc::UnboundedSender<crate::state::BakeEvent>>> {
        self.backend.share_events(events).await
    }
}
