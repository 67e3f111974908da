//! The embedded store: SQLite in WAL mode through sqlx. Writes that read
//! first (claims, completions) run in `BEGIN IMMEDIATE` transactions so
//! they take the write lock up front; `synchronous = FULL` makes every
//! acknowledged commit durable; a busy timeout waits out other writers.

use std::str::FromStr as _;
use std::time::Duration;

use sqlx::{
    FromRow as _, Row as _, SqliteConnection,
    sqlite::{
        SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteRow,
        SqliteSynchronous,
    },
};

use super::rows::{RawBake, RawJob, RawUpload, RawWorker};
use super::{
    Action, BakeRow, BakeState, Beat, CheckpointRef, Completion, JobRow, JobState, Lease, NewBake,
    QueuePolicy, Result, Store, StoreError, TokenRow, UploadRef, UploadRow, WorkerRow, lease_token,
};

/// The database clock, in milliseconds since the epoch.
const NOW: &str = "CAST(unixepoch('subsec') * 1000 AS INTEGER)";

/// SQLite behind the [`Store`] trait.
///
/// SQLite has one writer at a time, so writes go through one connection
/// in turn (a queue instead of busy-waiting) and reads through a pool.
/// Writes that acknowledge something a client relies on (an upload, a
/// bake, a completion, a failure, a control) commit with `synchronous =
/// FULL`; leases, heartbeats, checkpoints and reaping, which the queue
/// can lose in a power cut without harm (a lost lease is re-leased, a lost
/// checkpoint resumes from the one before), commit with `NORMAL`.
#[derive(Debug, Clone)]
pub struct SqliteStore {
    pool: SqlitePool,
    writer: SqlitePool,
    write_turn: std::sync::Arc<tokio::sync::Mutex<()>>,
}

/// How durable a write must be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Durability {
    /// fsync before the commit returns.
    Acknowledged,
    /// Survives a crash of the process, maybe not of the machine.
    Queue,
}

impl SqliteStore {
    /// Opens (creating if needed) the database at `path` and migrates it.
    pub async fn open(path: &std::path::Path) -> Result<Self> {
        let options = SqliteConnectOptions::from_str("sqlite://")?
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .busy_timeout(Duration::from_secs(10))
            .foreign_keys(true);
        let writer = SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(options.clone())
            .await?;
        sqlx::migrate!("migrations/sqlite").run(&writer).await?;
        let pool = SqlitePoolOptions::new()
            .max_connections(8)
            .connect_with(options.read_only(true))
            .await?;
        Ok(Self {
            pool,
            writer,
            write_turn: Default::default(),
        })
    }

    /// Waits for the writer's turn and sets its durability; the guard
    /// holds the turn until it is dropped.
    async fn turn(&self, durability: Durability) -> Result<tokio::sync::MutexGuard<'_, ()>> {
        let guard = self.write_turn.lock().await;
        let pragma = match durability {
            Durability::Acknowledged => "PRAGMA synchronous = FULL",
            Durability::Queue => "PRAGMA synchronous = NORMAL",
        };
        sqlx::query(pragma).execute(&self.writer).await?;
        Ok(guard)
    }

    async fn now(conn: &mut SqliteConnection) -> Result<i64> {
        Ok(sqlx::query_scalar(&format!("SELECT {NOW}"))
            .fetch_one(conn)
            .await?)
    }
}

fn bake_row(r: &SqliteRow) -> Result<BakeRow> {
    RawBake::from_row(r)?.cook()
}

fn job_row(r: &SqliteRow) -> Result<JobRow> {
    RawJob::from_row(r)?.cook()
}

/// Jobs with their dependencies' graph indices.
const JOB_SELECT: &str = "SELECT j.*, (SELECT group_concat(d.dep_idx) FROM (SELECT dep_idx FROM job_deps WHERE job_id = j.id ORDER BY dep_idx) d) AS deps FROM jobs j";

/// In an `UPDATE jobs … RETURNING`: the graph indices of the job's
/// dependencies, comma-separated.
const DEPS: &str = "(SELECT group_concat(d.dep_idx) FROM (SELECT dep_idx FROM job_deps WHERE job_id = jobs.id ORDER BY dep_idx) d)";

async fn bake_by_id(conn: &mut SqliteConnection, id: i64) -> Result<BakeRow> {
    let row = sqlx::query("SELECT * FROM bakes WHERE id = ?")
        .bind(id)
        .fetch_optional(conn)
        .await?
        .ok_or_else(|| StoreError::NotFound(format!("bake {id}")))?;
    bake_row(&row)
}

async fn job_by_id(conn: &mut SqliteConnection, id: i64) -> Result<JobRow> {
    let row = sqlx::query(&format!("{JOB_SELECT} WHERE j.id = ?"))
        .bind(id)
        .fetch_optional(conn)
        .await?
        .ok_or_else(|| StoreError::NotFound(format!("job {id}")))?;
    job_row(&row)
}

/// The job if `token` is its current lease, else `LeaseLost`.
async fn leased(conn: &mut SqliteConnection, job: i64, token: &str) -> Result<JobRow> {
    let held: Option<i64> = sqlx::query_scalar(
        "SELECT id FROM jobs WHERE id = ? AND lease_token = ? AND state = 'running'",
    )
    .bind(job)
    .bind(token)
    .fetch_optional(&mut *conn)
    .await?;
    if held.is_none() {
        return Err(StoreError::LeaseLost(format!(
            "job {job} is not leased with this token"
        )));
    }
    job_by_id(conn, job).await
}

/// After `job` completed: each dependent has one dependency fewer, and
/// those with none left become available. Touches only the job's direct
/// dependents, so a completion costs the same however large the bake.
async fn release_dependents(conn: &mut SqliteConnection, job: i64) -> Result<()> {
    // CASE sees the count before this update: 1 means this was the last.
    sqlx::query(
        "UPDATE jobs SET pending_deps = pending_deps - 1, state = CASE WHEN state = 'blocked' AND pending_deps = 1 THEN 'available' ELSE state END WHERE id IN (SELECT job_id FROM job_deps WHERE dep_id = ?)",
    )
    .bind(job)
    .execute(conn)
    .await?;
    Ok(())
}

/// Recounts the pending dependencies of the bake's blocked jobs and makes
/// those with none available (after a retry re-blocks jobs).
async fn unblock(conn: &mut SqliteConnection, bake: i64) -> Result<()> {
    sqlx::query(
        "UPDATE jobs SET pending_deps = (SELECT COUNT(*) FROM job_deps d JOIN jobs p ON p.id = d.dep_id WHERE d.job_id = jobs.id AND p.state != 'completed') WHERE bake_id = ? AND state = 'blocked'",
    )
    .bind(bake)
    .execute(&mut *conn)
    .await?;
    sqlx::query(
        "UPDATE jobs SET state = 'available' WHERE bake_id = ? AND state = 'blocked' AND pending_deps = 0",
    )
    .bind(bake)
    .execute(conn)
    .await?;
    Ok(())
}

/// Marks the bake failed when one of its jobs is dead.
async fn fail_bake_if_dead(conn: &mut SqliteConnection, bake: i64) -> Result<()> {
    sqlx::query(&format!(
        "UPDATE bakes SET state = 'failed', updated_at = {NOW}, finished_at = {NOW}, error = (SELECT 'job ' || idx || ' (' || kind || ') died after ' || attempts || ' attempts: ' || COALESCE(error, 'lease expired') FROM jobs WHERE bake_id = bakes.id AND state = 'dead' ORDER BY idx LIMIT 1) WHERE id = ? AND state IN ('queued', 'running', 'paused') AND EXISTS (SELECT 1 FROM jobs WHERE bake_id = bakes.id AND state = 'dead')"
    ))
    .bind(bake)
    .execute(conn)
    .await?;
    Ok(())
}

#[async_trait::async_trait]
impl Store for SqliteStore {
    async fn put_upload(&self, u: &UploadRow) -> Result<bool> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        let done = sqlx::query(&format!(
            "INSERT INTO uploads (digest, kind, bundle, bytes, summary, created_at) VALUES (?, ?, ?, ?, ?, {NOW}) ON CONFLICT (digest, kind) DO NOTHING"
        ))
        .bind(&u.digest)
        .bind(&u.kind)
        .bind(u.bundle)
        .bind(u.bytes)
        .bind(u.summary.to_string())
        .execute(&self.writer)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    async fn upload(&self, digest: &str, kind: &str) -> Result<Option<UploadRow>> {
        let row = sqlx::query("SELECT * FROM uploads WHERE digest = ? AND kind = ?")
            .bind(digest)
            .bind(kind)
            .fetch_optional(&self.pool)
            .await?;
        row.map(|r| RawUpload::from_row(&r)?.cook()).transpose()
    }

    async fn create_bake(&self, b: &NewBake) -> Result<BakeRow> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            let total: i64 = b.jobs.iter().map(|j| j.work).sum();
            let id: i64 = sqlx::query_scalar(&format!(
                "INSERT INTO bakes (key, character, clips, method, params, state, priority, total_work, jobs_total, created_at, updated_at) VALUES (?, ?, ?, ?, ?, 'queued', ?, ?, ?, {NOW}, {NOW}) RETURNING id"
            ))
            .bind(&b.key)
            .bind(&b.character)
            .bind(serde_json::to_string(&b.clips)?)
            .bind(&b.method)
            .bind(b.params.to_string())
            .bind(b.priority)
            .bind(total)
            .bind(b.jobs.len() as i64)
            .fetch_one(&mut *tx)
            .await?;
            let mut ids = Vec::with_capacity(b.jobs.len());
            for (i, j) in b.jobs.iter().enumerate() {
                let state = if j.deps.is_empty() {
                    "available"
                } else {
                    "blocked"
                };
                let job: i64 = sqlx::query_scalar(
                    "INSERT INTO jobs (bake_id, idx, kind, spec, work, state, max_attempts, pending_deps) VALUES (?, ?, ?, ?, ?, ?, ?, ?) RETURNING id",
                )
                .bind(id)
                .bind(i as i64)
                .bind(&j.kind)
                .bind(j.spec.to_string())
                .bind(j.work)
                .bind(state)
                .bind(b.max_attempts)
                .bind(j.deps.len() as i64)
                .fetch_one(&mut *tx)
                .await?;
                for &d in &j.deps {
                    let dep = *ids.get(d).ok_or_else(|| {
                        StoreError::Conflict(format!("job {i} depends on a later job {d}"))
                    })?;
                    sqlx::query("INSERT INTO job_deps (job_id, dep_id, dep_idx) VALUES (?, ?, ?)")
                        .bind(job)
                        .bind(dep)
                        .bind(d as i64)
                        .execute(&mut *tx)
                        .await?;
                }
                ids.push(job);
            }
            let bake = bake_by_id(&mut tx, id).await?;
            Ok(bake)
        })
    }

    async fn bake(&self, id: i64) -> Result<Option<BakeRow>> {
        let row = sqlx::query("SELECT * FROM bakes WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(bake_row).transpose()
    }

    async fn bake_for_key(&self, key: &str) -> Result<Option<BakeRow>> {
        let row = sqlx::query(
            "SELECT * FROM bakes WHERE key = ? AND state IN ('done', 'queued', 'running', 'paused') ORDER BY state = 'done' DESC, id DESC LIMIT 1",
        )
        .bind(key)
        .fetch_optional(&self.pool)
        .await?;
        row.as_ref().map(bake_row).transpose()
    }

    async fn bakes(
        &self,
        character: Option<&str>,
        method: Option<&str>,
        limit: i64,
    ) -> Result<Vec<BakeRow>> {
        let rows = sqlx::query(
            "SELECT * FROM bakes WHERE (?1 IS NULL OR character = ?1) AND (?2 IS NULL OR method = ?2) ORDER BY id DESC LIMIT ?3",
        )
        .bind(character)
        .bind(method)
        .bind(limit)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(bake_row).collect()
    }

    async fn jobs(&self, bake: i64) -> Result<Vec<JobRow>> {
        let rows = sqlx::query(&format!("{JOB_SELECT} WHERE j.bake_id = ? ORDER BY j.idx"))
            .bind(bake)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(job_row).collect()
    }

    async fn lease(&self, worker: &str, policy: &QueuePolicy) -> Result<Option<Lease>> {
        let _turn = self.turn(Durability::Queue).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            // Retries whose delay has passed are ready again.
            sqlx::query(&format!(
                "UPDATE jobs SET state = 'available' WHERE state = 'retryable' AND run_at <= {NOW}"
            ))
            .execute(&mut *tx)
            .await?;
            // The most urgent bake with a ready job that this worker is not
            // kept off, then its first ready job: two index lookups, however
            // many jobs are queued.
            let bake: Option<i64> = sqlx::query_scalar(&format!(
                "SELECT b.id FROM bakes b WHERE b.state IN ('queued', 'running') AND EXISTS (SELECT 1 FROM jobs j WHERE j.bake_id = b.id AND j.state = 'available') AND NOT EXISTS (SELECT 1 FROM worker_failures f WHERE f.bake_id = b.id AND f.worker = ?1 AND f.failures >= ?2 AND EXISTS (SELECT 1 FROM workers o WHERE o.id != ?1 AND o.last_seen > {NOW} - 60000 AND NOT EXISTS (SELECT 1 FROM worker_failures g WHERE g.bake_id = b.id AND g.worker = o.id AND g.failures >= ?2))) ORDER BY b.priority DESC, b.id LIMIT 1"
            ))
            .bind(worker)
            .bind(policy.worker_failures)
            .fetch_optional(&mut *tx)
            .await?;
            let id: Option<i64> = match bake {
                Some(bake) => {
                    sqlx::query_scalar(
                        "SELECT id FROM jobs WHERE bake_id = ? AND state = 'available' ORDER BY idx LIMIT 1",
                    )
                    .bind(bake)
                    .fetch_optional(&mut *tx)
                    .await?
                }
                None => None,
            };
            let Some(id) = id else {
                return Ok(None);
            };
            let token = lease_token();
            let job = sqlx::query_as::<_, RawJob>(&format!(
                "UPDATE jobs SET state = 'running', lease_token = ?, worker = ?, attempts = attempts + 1, lease_expires_at = {NOW} + ?, progress = 0 WHERE id = ? RETURNING *, {DEPS} AS deps"
            ))
            .bind(&token)
            .bind(worker)
            .bind(policy.lease_ms)
            .bind(id)
            .fetch_one(&mut *tx)
            .await?;
            let expires_at = job.lease_expires_at.unwrap_or_default();
            let job = job.cook()?;
            let bake = sqlx::query_as::<_, RawBake>(&format!(
                "UPDATE bakes SET state = CASE WHEN state = 'queued' THEN 'running' ELSE state END, updated_at = CASE WHEN state = 'queued' THEN {NOW} ELSE updated_at END WHERE id = ? RETURNING *"
            ))
            .bind(job.bake_id)
            .fetch_one(&mut *tx)
            .await?
            .cook()?;
            let deps = sqlx::query(
                "SELECT p.outputs, p.timings FROM job_deps d JOIN jobs p ON p.id = d.dep_id WHERE d.job_id = ? ORDER BY p.idx",
            )
            .bind(id)
            .fetch_all(&mut *tx)
            .await?;
            let mut inputs = Vec::new();
            for d in deps.iter().filter(|_| !job.deps.is_empty()) {
                let outputs: Option<String> = d.try_get("outputs")?;
                let timings: Option<String> = d.try_get("timings")?;
                inputs.push(Completion {
                    outputs: serde_json::from_str(outputs.as_deref().unwrap_or("[]"))?,
                    timings: serde_json::from_str(timings.as_deref().unwrap_or("null"))?,
                });
            }
            let mut uploads = Vec::new();
            for digest in std::iter::once(&bake.character).chain(&bake.clips) {
                let bundle: Option<bool> =
                    sqlx::query_scalar("SELECT bundle FROM uploads WHERE digest = ? LIMIT 1")
                        .bind(digest)
                        .fetch_optional(&mut *tx)
                        .await?;
                uploads.push(UploadRef {
                    digest: digest.clone(),
                    bundle: bundle.unwrap_or(false),
                });
            }
            sqlx::query(&format!(
                "INSERT INTO workers (id, state, job_id, last_seen, started_at) VALUES (?1, 'busy', ?2, {NOW}, {NOW}) ON CONFLICT (id) DO UPDATE SET state = 'busy', job_id = ?2, last_seen = {NOW}"
            ))
            .bind(worker)
            .bind(id)
            .execute(&mut *tx)
            .await?;
            Ok(Some(Lease {
                job,
                token,
                expires_at,
                bake,
                inputs,
                uploads,
            }))
        })
    }

    async fn heartbeat(
        &self,
        job: i64,
        token: &str,
        progress: i64,
        policy: &QueuePolicy,
    ) -> Result<Beat> {
        let _turn = self.turn(Durability::Queue).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            let j = leased(&mut tx, job, token).await?;
            sqlx::query(&format!(
                "UPDATE jobs SET lease_expires_at = {NOW} + ?, progress = ? WHERE id = ?"
            ))
            .bind(policy.lease_ms)
            .bind(progress.clamp(0, j.work))
            .bind(job)
            .execute(&mut *tx)
            .await?;
            let bake = bake_by_id(&mut tx, j.bake_id).await?;
            sqlx::query(&format!(
                "UPDATE workers SET last_seen = {NOW}, state = 'busy', job_id = ? WHERE id = ?"
            ))
            .bind(job)
            .bind(j.worker.as_deref().unwrap_or(""))
            .execute(&mut *tx)
            .await?;
            Ok(Beat {
                stop: !bake.state.is_active(),
                moved: progress.clamp(0, j.work) != j.progress,
                bake,
            })
        })
    }

    async fn checkpoint(&self, job: i64, token: &str, c: &CheckpointRef) -> Result<()> {
        let _turn = self.turn(Durability::Queue).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            leased(&mut tx, job, token).await?;
            sqlx::query(
                "UPDATE jobs SET checkpoint_step = ?, checkpoint_cursor = ?, checkpoint_blob = ? WHERE id = ?",
            )
            .bind(&c.step)
            .bind(c.cursor)
            .bind(&c.blob)
            .bind(job)
            .execute(&mut *tx)
            .await?;
            Ok(())
        })
    }

    async fn complete(&self, job: i64, token: &str, c: &Completion) -> Result<BakeRow> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        let digest = |name: &str| {
            c.outputs
                .iter()
                .find(|o| o.name == name)
                .map(|o| o.digest.clone())
        };
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            // Four statements: the completion (only with the current lease
            // token), the bake's counts (publishing the asset, report
            // and plot when this job produced them), the dependents, the worker.
            let done: Option<(i64, i64, Option<String>)> = sqlx::query_as(&format!(
                "UPDATE jobs SET state = 'completed', lease_token = NULL, lease_expires_at = NULL, progress = work, outputs = ?, timings = ?, error = NULL, finished_at = {NOW} WHERE id = ? AND lease_token = ? AND state = 'running' RETURNING bake_id, work, worker"
            ))
            .bind(serde_json::to_string(&c.outputs)?)
            .bind(c.timings.to_string())
            .bind(job)
            .bind(token)
            .fetch_optional(&mut *tx)
            .await?;
            let Some((bake_id, work, worker)) = done else {
                return Err(StoreError::LeaseLost(format!(
                    "job {job} is not leased with this token"
                )));
            };
            let bake = sqlx::query_as::<_, RawBake>(&format!(
                "UPDATE bakes SET done_work = done_work + ?, jobs_done = jobs_done + 1, updated_at = {NOW}, state = CASE WHEN jobs_done + 1 = jobs_total THEN 'done' ELSE state END, asset = COALESCE(?, asset), report = COALESCE(?, report), plot = COALESCE(?, plot), finished_at = CASE WHEN jobs_done + 1 = jobs_total THEN {NOW} ELSE finished_at END WHERE id = ? RETURNING *"
            ))
            .bind(work)
            .bind(digest("asset"))
            .bind(digest("report.json"))
            .bind(digest("plot.png"))
            .bind(bake_id)
            .fetch_one(&mut *tx)
            .await?
            .cook()?;
            release_dependents(&mut tx, job).await?;
            sqlx::query(&format!(
                "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {NOW} WHERE id = ?"
            ))
            .bind(worker.as_deref().unwrap_or(""))
            .execute(&mut *tx)
            .await?;
            Ok(bake)
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
        let _turn = self.turn(Durability::Acknowledged).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            let j = leased(&mut tx, job, token).await?;
            let dead = !retryable || j.attempts >= j.max_attempts;
            let now = Self::now(&mut tx).await?;
            sqlx::query(
                "UPDATE jobs SET state = ?, lease_token = NULL, lease_expires_at = NULL, run_at = ?, error = ? WHERE id = ?",
            )
            .bind(if dead { "dead" } else { "retryable" })
            .bind(now + policy.backoff_ms(j.attempts))
            .bind(error)
            .bind(job)
            .execute(&mut *tx)
            .await?;
            let worker = j.worker.as_deref().unwrap_or("");
            sqlx::query(
                "INSERT INTO worker_failures (bake_id, worker, failures) VALUES (?, ?, 1) ON CONFLICT (bake_id, worker) DO UPDATE SET failures = failures + 1",
            )
            .bind(j.bake_id)
            .bind(worker)
            .execute(&mut *tx)
            .await?;
            sqlx::query(&format!(
                "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {NOW} WHERE id = ?"
            ))
            .bind(worker)
            .execute(&mut *tx)
            .await?;
            fail_bake_if_dead(&mut tx, j.bake_id).await?;
            let bake = bake_by_id(&mut tx, j.bake_id).await?;
            Ok(bake)
        })
    }

    async fn release(&self, job: i64, token: &str) -> Result<()> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            let j = leased(&mut tx, job, token).await?;
            sqlx::query(
                "UPDATE jobs SET state = 'available', lease_token = NULL, lease_expires_at = NULL, attempts = attempts - 1 WHERE id = ?",
            )
            .bind(job)
            .execute(&mut *tx)
            .await?;
            sqlx::query(&format!(
                "UPDATE workers SET state = 'idle', job_id = NULL, last_seen = {NOW} WHERE id = ?"
            ))
            .bind(j.worker.as_deref().unwrap_or(""))
            .execute(&mut *tx)
            .await?;
            Ok(())
        })
    }

    async fn reap(&self) -> Result<u64> {
        let _turn = self.turn(Durability::Queue).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            // One statement decides which leases expired and frees them,
            // so a lease expiring meanwhile is either in both or in neither.
            let expired: Vec<(i64, i64)> = sqlx::query_as(&format!(
                "UPDATE jobs SET state = CASE WHEN attempts >= max_attempts THEN 'dead' ELSE 'retryable' END, run_at = {NOW}, lease_token = NULL, lease_expires_at = NULL, error = COALESCE(error, 'lease expired') WHERE state = 'running' AND lease_expires_at < {NOW} RETURNING id, bake_id"
            ))
            .fetch_all(&mut *tx)
            .await?;
            if expired.is_empty() {
                return Ok(0);
            }
            sqlx::query("UPDATE counters SET value = value + ? WHERE name = 'lease_expiries'")
                .bind(expired.len() as i64)
                .execute(&mut *tx)
                .await?;
            for &(_, bake) in &expired {
                fail_bake_if_dead(&mut tx, bake).await?;
            }
            Ok(expired.len() as u64)
        })
    }

    async fn control(&self, bake: i64, action: Action) -> Result<BakeRow> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        in_tx!(self.writer.begin_with("BEGIN IMMEDIATE").await?, |tx| {
            let b = bake_by_id(&mut tx, bake).await?;
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
                    sqlx::query(
                        "UPDATE jobs SET state = 'cancelled', lease_token = NULL, lease_expires_at = NULL WHERE bake_id = ? AND state NOT IN ('completed', 'dead')",
                    )
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                    sqlx::query(&format!(
                        "UPDATE bakes SET state = 'cancelled', finished_at = {NOW}, updated_at = {NOW} WHERE id = ?"
                    ))
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                }
                Action::Pause => {
                    if !matches!(b.state, BakeState::Queued | BakeState::Running) {
                        return refuse("only a queued or running bake can be paused");
                    }
                    sqlx::query(&format!(
                        "UPDATE bakes SET state = 'paused', updated_at = {NOW} WHERE id = ?"
                    ))
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                }
                Action::Resume => {
                    if b.state != BakeState::Paused {
                        return refuse("only a paused bake can be resumed");
                    }
                    sqlx::query(&format!(
                        "UPDATE bakes SET state = CASE WHEN jobs_done > 0 OR EXISTS (SELECT 1 FROM jobs WHERE bake_id = bakes.id AND state = 'running') THEN 'running' ELSE 'queued' END, updated_at = {NOW} WHERE id = ?"
                    ))
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                }
                Action::Retry => {
                    if !matches!(b.state, BakeState::Failed | BakeState::Cancelled) {
                        return refuse("only a failed or cancelled bake can be retried");
                    }
                    sqlx::query(
                        "UPDATE jobs SET state = 'blocked', attempts = 0, error = NULL, run_at = 0 WHERE bake_id = ? AND state IN ('dead', 'cancelled', 'retryable', 'available')",
                    )
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                    sqlx::query("DELETE FROM worker_failures WHERE bake_id = ?")
                        .bind(bake)
                        .execute(&mut *tx)
                        .await?;
                    unblock(&mut tx, bake).await?;
                    sqlx::query(&format!(
                        "UPDATE bakes SET state = 'queued', error = NULL, finished_at = NULL, updated_at = {NOW} WHERE id = ?"
                    ))
                    .bind(bake)
                    .execute(&mut *tx)
                    .await?;
                }
            }
            let b = bake_by_id(&mut tx, bake).await?;
            Ok(b)
        })
    }

    async fn set_priority(&self, bake: i64, priority: i64) -> Result<BakeRow> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        let mut conn = self.writer.acquire().await?;
        sqlx::query(&format!(
            "UPDATE bakes SET priority = ?, updated_at = {NOW} WHERE id = ?"
        ))
        .bind(priority)
        .bind(bake)
        .execute(&mut *conn)
        .await?;
        bake_by_id(&mut conn, bake).await
    }

    async fn worker_seen(&self, worker: &str, state: &str, job: Option<i64>) -> Result<()> {
        let _turn = self.turn(Durability::Queue).await?;
        sqlx::query(&format!(
            "INSERT INTO workers (id, state, job_id, last_seen, started_at) VALUES (?1, ?2, ?3, {NOW}, {NOW}) ON CONFLICT (id) DO UPDATE SET state = ?2, job_id = ?3, last_seen = {NOW}"
        ))
        .bind(worker)
        .bind(state)
        .bind(job)
        .execute(&self.writer)
        .await?;
        Ok(())
    }

    async fn workers(&self) -> Result<Vec<WorkerRow>> {
        let rows = sqlx::query("SELECT * FROM workers ORDER BY last_seen DESC, id")
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| Ok(RawWorker::from_row(r)?.cook()))
            .collect()
    }

    async fn create_token(&self, hash: &str, name: &str, scopes: &[String]) -> Result<()> {
        let _turn = self.turn(Durability::Acknowledged).await?;
        sqlx::query(&format!(
            "INSERT INTO tokens (hash, name, scopes, created_at) VALUES (?, ?, ?, {NOW}) ON CONFLICT (hash) DO UPDATE SET name = excluded.name, scopes = excluded.scopes"
        ))
        .bind(hash)
        .bind(name)
        .bind(scopes.join(","))
        .execute(&self.writer)
        .await?;
        Ok(())
    }

    async fn token(&self, hash: &str) -> Result<Option<TokenRow>> {
        let row: Option<(String, String)> =
            sqlx::query_as("SELECT name, scopes FROM tokens WHERE hash = ?")
                .bind(hash)
                .fetch_optional(&self.pool)
                .await?;
        Ok(row.map(|(name, scopes)| TokenRow {
            name,
            scopes: scopes.split(',').map(str::to_owned).collect(),
        }))
    }

    async fn queue_stats(&self) -> Result<(Vec<(JobState, i64)>, i64)> {
        let rows: Vec<(String, i64)> =
            sqlx::query_as("SELECT state, COUNT(*) FROM jobs GROUP BY state")
                .fetch_all(&self.pool)
                .await?;
        let expiries: i64 =
            sqlx::query_scalar("SELECT value FROM counters WHERE name = 'lease_expiries'")
                .fetch_one(&self.pool)
                .await?;
        Ok((
            rows.into_iter()
                .map(|(s, n)| (JobState::parse(&s), n))
                .collect(),
            expiries,
        ))
    }

    async fn ping(&self) -> Result<()> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[tokio::test]
    async fn the_shared_store_suite_passes_on_sqlite() {
        let dir = tempfile::tempdir().unwrap();
        let store = super::SqliteStore::open(&dir.path().join("t.db"))
            .await
            .unwrap();
        super::super::suite::run_all(&store).await;
    }
}
