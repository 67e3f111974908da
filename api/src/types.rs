//! The HTTP API's wire types: what the server answers and what its
//! clients send, as one set of serde types that the server, the worker and
//! the CLI share. With the `schema` feature each derives its OpenAPI
//! schema (utoipa), from which `api-spec/openapi.yaml` is generated.

use serde::{Deserialize, Serialize};

/// A stored upload.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct UploadRow {
    /// sha256 of the upload (its blob's digest).
    pub digest: String,
    /// `character` or `clips`.
    pub kind: String,
    /// Whether the blob is a bundle of a `.gltf` and its side files.
    pub bundle: bool,
    /// Blob size.
    pub bytes: i64,
    /// The `inspect` summary.
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub summary: serde_json::Value,
}

/// A bake's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum BakeState {
    /// Jobs wait for workers.
    Queued,
    /// A job has started.
    Running,
    /// No new jobs are leased; running ones finish.
    Paused,
    /// The asset is published.
    Done,
    /// A job died.
    Failed,
    /// Cancelled by a user.
    Cancelled,
}

/// A job's state (River's names, with `dead` for discarded).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Waiting for its dependencies.
    Blocked,
    /// Ready to lease.
    Available,
    /// Leased by a worker.
    Running,
    /// Failed or lost its lease; leasable again after `run_at`.
    Retryable,
    /// Finished; its outputs are final.
    Completed,
    /// Its bake was cancelled.
    Cancelled,
    /// Out of attempts.
    Dead,
}

/// A bake as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct BakeRow {
    /// Its id.
    pub id: i64,
    /// The bake key.
    pub key: String,
    /// Character digest.
    pub character: String,
    /// Clip digests.
    pub clips: Vec<String>,
    /// Method name.
    pub method: String,
    /// Fully defaulted parameters.
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub params: serde_json::Value,
    /// State.
    pub state: BakeState,
    /// Higher runs first.
    pub priority: i64,
    /// Units of work in all.
    pub total_work: i64,
    /// Units of work of completed jobs.
    pub done_work: i64,
    /// Work units the unfinished jobs have reached so far (the furthest
    /// any attempt of each got): with `done_work`, what a progress bar
    /// shows, which only moves forward while jobs are leased again.
    #[serde(default)]
    pub running_work: i64,
    /// Of `running_work`, the units running jobs are doing again (leased
    /// again after a lost lease, or run again for a lost output) before
    /// they pass where they had got.
    #[serde(default)]
    pub redo_work: i64,
    /// Jobs in all.
    pub jobs_total: i64,
    /// Jobs completed.
    pub jobs_done: i64,
    /// Asset digest, once done.
    pub asset: Option<String>,
    /// Report digest, once done.
    pub report: Option<String>,
    /// Plot digest, once done.
    pub plot: Option<String>,
    /// Why it failed.
    pub error: Option<String>,
    /// Milliseconds since the epoch.
    pub created_at: i64,
    /// Milliseconds since the epoch.
    pub updated_at: i64,
    /// Milliseconds since the epoch.
    pub finished_at: Option<i64>,
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct JobRow {
    /// Its id.
    pub id: i64,
    /// Its bake.
    pub bake_id: i64,
    /// Index in the bake's graph.
    pub index: i64,
    /// `sample`, `fit`, …
    pub kind: String,
    /// The job spec (core's `JobSpec`).
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub spec: serde_json::Value,
    /// Units of work.
    pub work: i64,
    /// State.
    pub state: JobState,
    /// Leases so far.
    pub attempts: i64,
    /// Leases allowed.
    pub max_attempts: i64,
    /// The worker holding or last holding it.
    pub worker: Option<String>,
    /// Units done in the current attempt.
    pub progress: i64,
    /// The furthest any attempt got (units): a job leased again does its
    /// work again up to here before its bake's progress moves on.
    #[serde(default)]
    pub reached: i64,
    /// Last checkpoint: step, cursor and blob.
    pub checkpoint: Option<CheckpointRef>,
    /// Outputs, once completed.
    pub outputs: Option<Vec<OutputRef>>,
    /// The last error.
    pub error: Option<String>,
    /// When its current (or last) attempt was leased, in milliseconds
    /// since the epoch.
    #[serde(default)]
    pub started_at: Option<i64>,
    /// When it completed, in milliseconds since the epoch.
    #[serde(default)]
    pub finished_at: Option<i64>,
    /// Indices of the jobs it needs.
    pub deps: Vec<i64>,
}

/// A checkpoint saved as a blob.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CheckpointRef {
    /// Named step.
    pub step: String,
    /// Cursor within it.
    pub cursor: i64,
    /// Blob digest of its data.
    pub blob: String,
}

/// A named output blob of a job.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct OutputRef {
    /// Output name.
    pub name: String,
    /// Blob digest.
    pub digest: String,
}

/// A leased job and what the worker needs to run it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Lease {
    /// The job.
    pub job: JobRow,
    /// The token `heartbeat`, `checkpoint` and `complete` must present.
    pub token: String,
    /// When the lease expires unless extended (ms since the epoch).
    pub expires_at: i64,
    /// The bake it belongs to.
    pub bake: BakeRow,
    /// Outputs of its dependencies, one entry per dependency.
    pub inputs: Vec<Completion>,
    /// The bake's uploads: whether each is a bundle (character first).
    pub uploads: Vec<UploadRef>,
}

/// An upload a job reads.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct UploadRef {
    /// Blob digest.
    pub digest: String,
    /// Whether the blob is a bundle.
    pub bundle: bool,
}

/// What a completing worker hands in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Completion {
    /// Output blobs, already stored.
    pub outputs: Vec<OutputRef>,
    /// Stage seconds, for the report.
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub timings: serde_json::Value,
}

/// Changes to a bake's course.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Action {
    /// Stop it for good.
    Cancel,
    /// Lease no more of its jobs.
    Pause,
    /// Lease them again.
    Resume,
    /// Re-queue its dead and cancelled jobs with fresh attempts, and
    /// its completed jobs whose outputs the blob store lost.
    Retry,
}

/// A worker as last seen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct WorkerRow {
    /// Its id.
    pub id: String,
    /// `idle`, `busy`, or `stopped`: it said so on its way out
    /// (`POST /v1/workers/stopped`), or was not seen for a lease's length
    /// (it exited, was killed or is cut off; a live worker polls or
    /// heartbeats well within a lease).
    pub state: String,
    /// The job it runs.
    pub job_id: Option<i64>,
    /// The bake of the job it runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bake_id: Option<i64>,
    /// Last contact (ms since the epoch).
    pub last_seen: i64,
    /// First contact.
    pub started_at: i64,
    /// What casts its rays, as it last said: `cpu`, or `gpu: ` and the
    /// adapter (`aobake worker --gpu`).
    #[serde(default = "cpu")]
    pub tracer: String,
}

fn cpu() -> String {
    "cpu".to_owned()
}

/// What an upload answers.
#[derive(Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Uploaded {
    pub digest: String,
    /// The `aobake inspect` summary (clips, vertices, joints, warnings).
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub summary: serde_json::Value,
}

/// `POST /v1/bakes`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct BakeRequest {
    /// The character's upload digest.
    #[cfg_attr(feature = "schema", schema(value_type = String, pattern = "^[0-9a-f]{64}$"))]
    pub character: String,
    /// Clip upload digests (at most 256, each once).
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(value_type = Vec<String>))]
    pub clips: Vec<String>,
    #[cfg_attr(feature = "schema", schema(schema_with = crate::schema::method))]
    pub method: String,
    /// Overrides of the method's default parameters (`aobake params
    /// --method M` lists them), by name; dotted names or nested objects
    /// for method options. Unknown names and another method's options
    /// are refused (400).
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub params: serde_json::Map<String, serde_json::Value>,
    #[serde(default)]
    pub priority: i64,
}

/// `POST /v1/keys`: the bake key a request would have, computed by the
/// server (the same code as a bake's) without uploading or baking; then
/// `GET /v1/cache/{key}` answers the finished bake, if there is one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct BakeKey {
    /// The key: sha256 of the canonical request (docs/asset-format.md).
    #[cfg_attr(feature = "schema", schema(pattern = "^[0-9a-f]{64}$"))]
    pub key: String,
    /// The method's algorithm version, which the key includes.
    pub algorithm_version: u32,
    /// The parameters with every default filled in, as the key hashes
    /// them.
    #[cfg_attr(feature = "schema", schema(value_type = Object))]
    pub params: serde_json::Value,
}

/// Progress of a bake in units of work.
#[derive(Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Progress {
    /// Units done: finished jobs' work and how far the others got. It
    /// only moves forward, also when jobs are leased again.
    pub done: i64,
    /// Units in all.
    pub total: i64,
    /// Of `done`, the units being done again (jobs leased again after a
    /// lost lease or run again for a lost output), until they pass where
    /// they had got.
    #[serde(default)]
    pub redo: i64,
}

/// A bake as the API shows it.
#[derive(Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct BakeView {
    #[serde(flatten)]
    pub bake: BakeRow,
    pub progress: Progress,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jobs: Option<Vec<JobRow>>,
    /// In a submit's answer: the finished bake with the same key whose
    /// asset or report the blob store lost, which this new bake makes
    /// again (the cache never answers with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rebakes: Option<i64>,
}

/// One preview image of a bake.
#[derive(Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct PreviewItem {
    /// Output name, such as `still-0.png` or `animation.png`.
    pub name: String,
    /// `still` (truth, model, screen-space AO and the model's error side
    /// by side), `unseen` (a still of a clip an unseen-clip fold left out,
    /// drawn with the fold's model) or `animation` (an
    /// APNG of a whole clip, model beside truth).
    pub kind: String,
    /// The clip shown, if any.
    pub clip: Option<String>,
    /// Clip times shown, in seconds.
    pub times: Vec<f32>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The adapter that rendered it (name, backend, driver).
    pub adapter: String,
    /// Milliseconds per rendered panel.
    pub frame_ms: f64,
    /// Seconds spent ray tracing its ground truth.
    pub trace_s: f64,
    /// A still's screen-space baseline (GTAO) beside the model: each
    /// one's errors against per-pixel ray-traced AO on the character and
    /// the ground, and each one's milliseconds per frame on the adapter
    /// (core's `bake::screen_space::ScreenSpaceInfo`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "schema", schema(value_type = Option<Object>))]
    pub screen_space: Option<serde_json::Value>,
    /// sha256 of the PNG: `GET /v1/previews/{digest}`.
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(value_type = String, pattern = "^[0-9a-f]{64}$"))]
    pub digest: String,
}

/// `GET /v1/bakes/{id}/previews`.
#[derive(Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct PreviewList {
    /// The state of the bake's `preview` job (none for a graph without
    /// one).
    pub state: Option<JobState>,
    /// The images, once the job has completed.
    pub previews: Vec<PreviewItem>,
    /// Why the job completed without images (its worker had no GPU
    /// adapter, not even a software one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unavailable: Option<String>,
    /// The stills' per-pixel errors on the character, pooled per clip:
    /// the bake's model on its preview clip and (texel bakes) each
    /// unseen-clip fold's model on the clip it left out, beside the static
    /// average, the texel and per-vertex floors and GTAO (core's
    /// `bake::screen_space::PixelSummary`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "schema", schema(value_type = Option<Object>))]
    pub pixels: Option<serde_json::Value>,
}

// `PATCH /v1/bakes/{id}`: the new priority.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct PatchBody {
    pub priority: i64,
}

/// `POST /v1/jobs/lease`.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct LeaseRequest {
    /// The worker's id.
    #[cfg_attr(feature = "schema", schema(min_length = 1, max_length = 200))]
    pub worker: String,
    /// Seconds to wait for a job before answering 204 (at most 60).
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(maximum = 60))]
    pub wait_secs: u64,
    /// What casts the worker's rays: `cpu`, or `gpu: ` and the adapter;
    /// shown in `GET /v1/workers`. A process sends it with its first
    /// request, which marks it started (`started_at`), also under an id
    /// used before.
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(max_length = 200))]
    pub tracer: Option<String>,
    /// The request's nonce, as in `LeaseManyRequest`.
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(max_length = 64))]
    pub request: Option<String>,
}

/// `POST /v1/jobs/leases`: jobs for several idle slots of one worker
/// process in one request.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct LeaseManyRequest {
    /// The idle slots' worker ids (1 to 64, each 1 to 200 characters, no
    /// repeats): each gets at most one job.
    #[cfg_attr(feature = "schema", schema(min_items = 1, max_items = 64))]
    pub workers: Vec<String>,
    /// Seconds to wait for a first job before answering 204 (at most 60).
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(maximum = 60))]
    pub wait_secs: u64,
    /// What casts the process's rays, as in `LeaseRequest`.
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(max_length = 200))]
    pub tracer: Option<String>,
    /// A nonce the worker sends again, unchanged, when it asks again after
    /// getting no answer (a server that died after leasing, a dropped
    /// connection; 1 to 64 characters): a job that request leased and
    /// that still runs under one of its slots is answered again, with the
    /// same token and attempt and its lease renewed, instead of waiting
    /// out its lease to run a second time. A new request, after an
    /// answer, takes a new nonce.
    #[serde(default)]
    #[cfg_attr(feature = "schema", schema(max_length = 64))]
    pub request: Option<String>,
}

/// `POST /v1/workers/stopped`: the slots of a worker process that is
/// exiting (after its jobs finished or were given back).
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct WorkersStopped {
    /// The slots' worker ids (1 to 64, each 1 to 200 characters).
    #[cfg_attr(feature = "schema", schema(min_items = 1, max_items = 64))]
    pub workers: Vec<String>,
}

/// Leased jobs, at most one per slot asked for, in the order asked; fewer
/// slots than asked get one when fewer jobs are ready.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Leases {
    /// The leases; each job's `worker` names its slot.
    pub leases: Vec<Lease>,
}

/// One job's completion in `POST /v1/jobs/completions`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct JobCompletion {
    /// The job.
    pub job: i64,
    /// Its lease token.
    pub token: String,
    /// Its outputs (blobs already stored) and timings.
    pub completion: Completion,
}

/// `POST /v1/jobs/completions`: several jobs' completions in one request
/// and one transaction.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CompleteManyRequest {
    /// 1 to 64 completions.
    #[cfg_attr(feature = "schema", schema(min_items = 1, max_items = 64))]
    pub completions: Vec<JobCompletion>,
}

/// What became of each completion, in the order sent.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CompleteManyReply {
    /// One result per completion sent.
    pub results: Vec<CompletionResult>,
}

/// One completion's outcome: recorded, or refused with the problem a
/// single `complete` would have answered (409 when the lease is gone, 400
/// `missing_blob` when an output was not stored).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CompletionResult {
    /// The job.
    pub job: i64,
    /// Why it was refused; absent when it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problem: Option<Problem>,
}

/// Token and progress.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct HeartbeatRequest {
    /// The lease token.
    pub token: String,
    /// Units done in this attempt.
    #[serde(default)]
    pub progress: i64,
}

/// Whether the worker should stop.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct HeartbeatReply {
    /// The bake ended (cancelled, or failed by another job): stop and
    /// drop the job.
    pub stop: bool,
    /// The bake's state, which says why a stop was asked (`cancelled`,
    /// `failed`).
    #[serde(default)]
    pub bake_state: Option<BakeState>,
}

/// A checkpoint whose blob is stored.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CheckpointRequest {
    /// The lease token.
    pub token: String,
    /// Step, cursor and blob.
    #[serde(flatten)]
    pub checkpoint: CheckpointRef,
}

/// Outputs whose blobs are stored.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct CompleteRequest {
    /// The lease token.
    pub token: String,
    /// Outputs and timings.
    #[serde(flatten)]
    pub completion: Completion,
}

/// Why an attempt failed.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct FailRequest {
    /// The lease token.
    pub token: String,
    /// What went wrong.
    pub error: String,
    /// Whether another attempt can help.
    pub retryable: bool,
}

/// The lease token alone.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct TokenRequest {
    /// The lease token.
    pub token: String,
}

/// The caller's token, as `GET /v1/whoami` shows it.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Whoami {
    /// The token's name.
    pub name: String,
    /// Its scopes (`admin` implies every other).
    pub scopes: Vec<String>,
}

/// A token as `GET /v1/tokens` lists it: never its secret.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct TokenView {
    /// sha256 of the secret, lower-case hex: what `DELETE /v1/tokens/{id}`
    /// takes.
    #[cfg_attr(feature = "schema", schema(pattern = "^[0-9a-f]{64}$"))]
    pub id: String,
    /// Its name.
    pub name: String,
    /// Its scopes.
    pub scopes: Vec<String>,
    /// Milliseconds since the epoch.
    pub created_at: i64,
    /// When it stops being valid (ms since the epoch); absent: never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expires_at: Option<i64>,
    /// When a request last used it (ms since the epoch, to the minute);
    /// absent: never used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_used_at: Option<i64>,
    /// Whether it is the token of this request.
    pub current: bool,
}

/// `POST /v1/tokens`.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct NewTokenRequest {
    /// A name to recognise it by.
    pub name: String,
    /// Its scopes.
    #[cfg_attr(feature = "schema", schema(schema_with = crate::schema::scopes))]
    pub scopes: Vec<String>,
    /// Seconds it is valid for (1 s to [`MAX_TOKEN_SECS`], ten years);
    /// absent: until revoked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "schema", schema(minimum = 1, maximum = 315_360_000))]
    pub expires_in_secs: Option<u64>,
}

/// The longest a token may be made valid for: ten years, in seconds.
pub const MAX_TOKEN_SECS: u64 = 315_360_000;

/// The new token: shown once, stored hashed.
#[derive(Debug, Deserialize, Serialize)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct NewToken {
    /// The secret.
    pub token: String,
    /// Its name.
    pub name: String,
    /// Its scopes.
    pub scopes: Vec<String>,
    /// When it stops being valid (ms since the epoch); absent: never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expires_at: Option<i64>,
}

/// The problem+json body.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "schema", derive(utoipa::ToSchema))]
pub struct Problem {
    /// A URI naming the problem type.
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary.
    pub title: String,
    /// HTTP status.
    pub status: u16,
    /// What went wrong with this request.
    pub detail: String,
    /// Machine-readable code.
    pub code: String,
    /// For an upload that cannot be imported (422 `invalid_upload`): the
    /// importer's machine-readable reason, one of `gltf_container`,
    /// `gltf_json`, `limit_exceeded`, `forbidden_uri`, `missing_file`,
    /// `unsupported_extension`, `gltf_invalid`, `no_geometry` and
    /// `no_animations` (docs/import-policy.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// For an upload that cannot be imported: where in the file's glTF
    /// JSON, as an RFC 6901 JSON Pointer (`/accessors/3`), when the
    /// reason is at one place.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pointer: Option<String>,
}

impl BakeRequest {
    /// A request to bake `character` (an upload digest) with `method` and
    /// the parameter overrides `params`, without clips, at priority 0.
    pub fn new(
        character: String,
        method: &str,
        params: serde_json::Map<String, serde_json::Value>,
    ) -> Self {
        Self {
            character,
            clips: Vec::new(),
            method: method.to_owned(),
            params,
            priority: 0,
        }
    }
}

impl BakeState {
    /// Every state.
    pub const ALL: [Self; 6] = [
        Self::Queued,
        Self::Running,
        Self::Paused,
        Self::Done,
        Self::Failed,
        Self::Cancelled,
    ];

    /// As stored and sent.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Running => "running",
            Self::Paused => "paused",
            Self::Done => "done",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }

    /// The state spelled `s` (`queued` for anything else).
    pub fn parse(s: &str) -> Self {
        Self::ALL
            .into_iter()
            .find(|x| x.as_str() == s)
            .unwrap_or(Self::Queued)
    }

    /// Whether the bake can still change.
    pub fn is_active(self) -> bool {
        matches!(self, Self::Queued | Self::Running | Self::Paused)
    }
}

impl JobState {
    /// Every state, for metrics.
    pub const ALL: [Self; 7] = [
        Self::Blocked,
        Self::Available,
        Self::Running,
        Self::Retryable,
        Self::Completed,
        Self::Cancelled,
        Self::Dead,
    ];

    /// As stored and sent.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Blocked => "blocked",
            Self::Available => "available",
            Self::Running => "running",
            Self::Retryable => "retryable",
            Self::Completed => "completed",
            Self::Cancelled => "cancelled",
            Self::Dead => "dead",
        }
    }

    /// The state spelled `s` (`blocked` for anything else).
    pub fn parse(s: &str) -> Self {
        Self::ALL
            .into_iter()
            .find(|x| x.as_str() == s)
            .unwrap_or(Self::Blocked)
    }
}

/// A token's scope.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// See bakes, reports, published assets, previews, workers.
    Read,
    /// Everything `read` allows; upload, read back what was uploaded,
    /// and bake.
    Submit,
    /// Run jobs.
    Worker,
    /// Everything, and tokens.
    Admin,
}

impl Scope {
    /// Every scope.
    pub const ALL: [Self; 4] = [Self::Read, Self::Submit, Self::Worker, Self::Admin];

    /// As stored and as `--scope` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Submit => "submit",
            Self::Worker => "worker",
            Self::Admin => "admin",
        }
    }

    /// The scope named `s`.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }

    /// Whether a token with this scope may do what `other` allows:
    /// `admin` everything, `submit` also `read` (a build system follows
    /// and fetches the bakes it submits).
    pub fn includes(self, other: Self) -> bool {
        self == other || self == Self::Admin || (self == Self::Submit && other == Self::Read)
    }
}
