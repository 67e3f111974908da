//! Rows as both backends store them, decoded by one `sqlx::FromRow` derive
//! (generic over the database), then turned into the store's types.

use super::{
    BakeRow, BakeState, CheckpointRef, JobRow, JobState, Result, TokenRow, UploadRow, WorkerRow,
};

#[derive(sqlx::FromRow)]
pub(super) struct RawUpload {
    digest: String,
    kind: String,
    bundle: bool,
    bytes: i64,
    summary: String,
}

impl RawUpload {
    pub(super) fn cook(self) -> Result<UploadRow> {
        Ok(UploadRow {
            digest: self.digest,
            kind: self.kind,
            bundle: self.bundle,
            bytes: self.bytes,
            summary: serde_json::from_str(&self.summary)?,
        })
    }
}

#[derive(sqlx::FromRow)]
pub(super) struct RawBake {
    id: i64,
    key: String,
    character: String,
    clips: String,
    method: String,
    params: String,
    state: String,
    priority: i64,
    total_work: i64,
    done_work: i64,
    /// Computed where a query selects it (`bake_columns` in
    /// [`super::queue`]); else filled in after, or 0 where it is.
    #[sqlx(default)]
    running_work: i64,
    /// Computed with `running_work`.
    #[sqlx(default)]
    redo_work: i64,
    jobs_total: i64,
    jobs_done: i64,
    asset: Option<String>,
    report: Option<String>,
    plot: Option<String>,
    error: Option<String>,
    created_at: i64,
    updated_at: i64,
    finished_at: Option<i64>,
}

impl RawBake {
    pub(super) fn cook(self) -> Result<BakeRow> {
        Ok(BakeRow {
            id: self.id,
            key: self.key,
            character: self.character,
            clips: serde_json::from_str(&self.clips)?,
            method: self.method,
            params: serde_json::from_str(&self.params)?,
            state: BakeState::parse(&self.state),
            priority: self.priority,
            total_work: self.total_work,
            done_work: self.done_work,
            running_work: self.running_work,
            redo_work: self.redo_work,
            jobs_total: self.jobs_total,
            jobs_done: self.jobs_done,
            asset: self.asset,
            report: self.report,
            plot: self.plot,
            error: self.error,
            created_at: self.created_at,
            updated_at: self.updated_at,
            finished_at: self.finished_at,
        })
    }
}

#[derive(sqlx::FromRow)]
pub(super) struct RawJob {
    id: i64,
    bake_id: i64,
    idx: i64,
    kind: String,
    spec: String,
    work: i64,
    state: String,
    attempts: i64,
    max_attempts: i64,
    worker: Option<String>,
    pub(super) lease_expires_at: Option<i64>,
    progress: i64,
    reached: i64,
    checkpoint_step: Option<String>,
    checkpoint_cursor: Option<i64>,
    checkpoint_blob: Option<String>,
    outputs: Option<String>,
    error: Option<String>,
    started_at: Option<i64>,
    finished_at: Option<i64>,
    /// Graph indices of the dependencies, comma-separated.
    deps: Option<String>,
}

impl RawJob {
    pub(super) fn cook(self) -> Result<JobRow> {
        let checkpoint = match (
            self.checkpoint_step,
            self.checkpoint_cursor,
            self.checkpoint_blob,
        ) {
            (Some(step), Some(cursor), Some(blob)) => Some(CheckpointRef { step, cursor, blob }),
            _ => None,
        };
        Ok(JobRow {
            id: self.id,
            bake_id: self.bake_id,
            index: self.idx,
            kind: self.kind,
            spec: serde_json::from_str(&self.spec)?,
            work: self.work,
            state: JobState::parse(&self.state),
            attempts: self.attempts,
            max_attempts: self.max_attempts,
            worker: self.worker,
            progress: self.progress,
            reached: self.reached,
            checkpoint,
            outputs: self.outputs.map(|o| serde_json::from_str(&o)).transpose()?,
            error: self.error,
            started_at: self.started_at,
            finished_at: self.finished_at,
            deps: self
                .deps
                .map(|d| d.split(',').filter_map(|x| x.parse().ok()).collect())
                .unwrap_or_default(),
        })
    }
}

#[derive(sqlx::FromRow)]
pub(super) struct RawWorker {
    id: String,
    state: String,
    job_id: Option<i64>,
    bake_id: Option<i64>,
    last_seen: i64,
    started_at: i64,
    tracer: String,
}

impl RawWorker {
    pub(super) fn cook(self) -> WorkerRow {
        WorkerRow {
            id: self.id,
            state: self.state,
            job_id: self.job_id,
            bake_id: self.bake_id,
            last_seen: self.last_seen,
            started_at: self.started_at,
            tracer: self.tracer,
        }
    }
}

/// A token's row as the database holds it.
#[derive(sqlx::FromRow)]
pub(super) struct RawToken {
    hash: String,
    name: String,
    scopes: String,
    created_at: i64,
    expires_at: Option<i64>,
    last_used_at: Option<i64>,
}

impl RawToken {
    /// Its hash and row.
    pub(super) fn cook(self) -> (String, TokenRow) {
        (
            self.hash,
            TokenRow {
                name: self.name,
                scopes: self.scopes.split(',').map(str::to_owned).collect(),
                created_at: self.created_at,
                expires_at: self.expires_at,
                last_used_at: self.last_used_at,
            },
        )
    }
}
