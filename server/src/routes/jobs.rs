//! The worker protocol: lease (long-polled), heartbeat, checkpoint,
//! complete, fail and release, each but lease checked against the job's
//! current lease token (a stale one gets 409), and the blobs workers read
//! and write.

use aobake_api::schema::{Digest, Refusals};
use aobake_api::{
    CheckpointRequest, CompleteManyReply, CompleteManyRequest, CompleteRequest, CompletionResult,
    FailRequest, HeartbeatReply, HeartbeatRequest, LeaseManyRequest, LeaseRequest, Leases,
    TokenRequest, WorkersStopped,
};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use axum::{
    Extension, Json, Router,
    body::Bytes,
    extract::State,
    http::StatusCode,
    response::{IntoResponse, Response},
    routing::{get, post},
};

use crate::{
    app::ClientGone,
    auth::{Need, Worker},
    error::{ApiError, ApiResult, Problem},
    extract::{ApiPath, Body},
    state::AppState,
    store::{JobCompletion, Lease},
};

/// The most jobs one `leases` or `completions` request may carry.
const MAX_BATCH: usize = 64;

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/jobs/lease", post(lease))
        .route("/v1/jobs/leases", post(lease_many))
        .route("/v1/jobs/completions", post(complete_many))
        .route("/v1/jobs/{id}/heartbeat", post(heartbeat))
        .route("/v1/jobs/{id}/checkpoint", post(checkpoint))
        .route("/v1/jobs/{id}/complete", post(complete))
        .route("/v1/jobs/{id}/fail", post(fail))
        .route("/v1/jobs/{id}/release", post(release))
        .route("/v1/workers/stopped", post(workers_stopped))
        .route("/v1/blobs/{digest}", get(get_blob).put(put_blob))
}

#[utoipa::path(post, path = "/v1/jobs/lease", tag = "worker protocol", request_body = LeaseRequest,
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "A leased job", body = Lease), (status = 204, description = "No job within wait_secs"), Refusals))]
pub(crate) async fn lease(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    gone: Option<Extension<ClientGone>>,
    Body(req): Body<LeaseRequest>,
) -> ApiResult<Response> {
    let workers = vec![req.worker];
    check_slots(&workers, "a lease request")?;
    let ask = Ask {
        wait_secs: req.wait_secs,
        tracer: req.tracer,
        request: req.request,
    };
    let leases = wait_for_leases(&state, workers, ask, gone).await?;
    Ok(match leases.into_iter().next() {
        Some(lease) => Json(lease).into_response(),
        None => StatusCode::NO_CONTENT.into_response(),
    })
}

#[utoipa::path(post, path = "/v1/jobs/leases", tag = "worker protocol", request_body = LeaseManyRequest,
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "One to all of the slots got a job", body = Leases), (status = 204, description = "No job within wait_secs"), Refusals))]
pub(crate) async fn lease_many(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    gone: Option<Extension<ClientGone>>,
    Body(req): Body<LeaseManyRequest>,
) -> ApiResult<Response> {
    check_slots(&req.workers, "a lease request")?;
    let ask = Ask {
        wait_secs: req.wait_secs,
        tracer: req.tracer,
        request: req.request,
    };
    let leases = wait_for_leases(&state, req.workers, ask, gone).await?;
    Ok(if leases.is_empty() {
        StatusCode::NO_CONTENT.into_response()
    } else {
        Json(Leases { leases }).into_response()
    })
}

/// A worker process's slots as a request names them: 1 to
/// [`MAX_BATCH`], each once, each id 1 to 200 characters.
fn check_slots(workers: &[String], what: &str) -> ApiResult<()> {
    if workers.is_empty() || workers.len() > MAX_BATCH {
        return Err(ApiError::bad(
            "bad_workers",
            format!("{what} names 1 to {MAX_BATCH} workers"),
        ));
    }
    if workers.iter().collect::<BTreeSet<_>>().len() != workers.len() {
        return Err(ApiError::bad(
            "bad_workers",
            format!("{what} names each worker once"),
        ));
    }
    if workers.iter().any(|w| w.is_empty() || w.len() > 200) {
        return Err(ApiError::bad(
            "bad_worker",
            "worker ids are 1 to 200 characters",
        ));
    }
    Ok(())
}

#[utoipa::path(post, path = "/v1/workers/stopped", tag = "worker protocol", request_body = WorkersStopped,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Recorded: the workers are listed as stopped"), Refusals))]
pub(crate) async fn workers_stopped(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    Body(req): Body<WorkersStopped>,
) -> ApiResult<StatusCode> {
    check_slots(&req.workers, "a stop")?;
    state.store.workers_stopped(&req.workers).await?;
    // A stopped GPU worker no longer holds tracing jobs back from CPU
    // workers: wake the waiting polls.
    state.jobs_ready.notify_waiters();
    Ok(StatusCode::NO_CONTENT)
}

/// What a lease request asks besides its slots.
struct Ask {
    /// Seconds to wait for a first job (at most 60).
    wait_secs: u64,
    /// The process's tracer, when it tells it.
    tracer: Option<String>,
    /// The request's nonce (`LeaseManyRequest::request`).
    request: Option<String>,
}

/// Leases for `workers` ([`check_slots`]), waiting up to `wait_secs` (at most 60) for a
/// first job; empty when none came, or once the worker that asked has
/// gone (its connection closed: a worker stopped mid-poll, or killed), so
/// that no job is leased to a worker that will never run it.
async fn wait_for_leases(
    state: &AppState,
    workers: Vec<String>,
    Ask {
        wait_secs,
        tracer,
        request,
    }: Ask,
    gone: Option<Extension<ClientGone>>,
) -> ApiResult<Vec<Lease>> {
    let mut gone = gone.map(|Extension(g)| g);
    if request
        .as_ref()
        .is_some_and(|r| r.is_empty() || r.len() > 64)
    {
        return Err(ApiError::bad(
            "bad_request_nonce",
            "a lease request's nonce is 1 to 64 characters",
        ));
    }
    if let Some(tracer) = &tracer {
        if tracer.is_empty() || tracer.len() > 200 {
            return Err(ApiError::bad(
                "bad_tracer",
                "a worker's tracer is 1 to 200 characters",
            ));
        }
        for worker in &workers {
            state.store.worker_tracer(worker, tracer).await?;
        }
    }
    let deadline = tokio::time::Instant::now() + Duration::from_secs(wait_secs.min(60));
    let mut first = true;
    loop {
        if gone.as_ref().is_some_and(ClientGone::is_gone) {
            return Ok(Vec::new());
        }
        // A process that said it stopped while this poll was open no
        // longer listens for its answer: no job for it, and it stays
        // listed as stopped.
        if !first && !state.store.workers_still_waiting(&workers).await? {
            return Ok(Vec::new());
        }
        // Register interest before looking, so a job made available between
        // the look and the wait still wakes us.
        let notified = state.jobs_ready.notified();
        let leases = state
            .store
            .lease_batch(&workers, request.as_deref(), &state.policy)
            .await?;
        if !leases.is_empty() && gone.as_ref().is_some_and(ClientGone::is_gone) {
            // The worker went while its jobs were being leased: give them
            // back now rather than at their leases' expiry.
            // Each on its own: one that fails expires, the others do not
            // wait for it.
            for l in &leases {
                // Unless renewed since: the same request, sent again by
                // a worker that got no answer, may have it back already.
                let leased_until = Some(l.expires_at);
                if let Err(e) = state
                    .store
                    .release_unless_renewed(l.job.id, &l.token, leased_until)
                    .await
                {
                    log_line!(
                        "error: job {} stays leased to a worker that went, until its lease expires: {e}",
                        l.job.id
                    );
                }
            }
            return Ok(Vec::new());
        }
        if !leases.is_empty() {
            // Each lease carries its bake's row as the lease left it.
            let mut announced = BTreeSet::new();
            for l in &leases {
                if announced.insert(l.bake.id) {
                    state.announce(&l.bake);
                }
            }
            return Ok(leases);
        }
        if first {
            // A poll's first look says the slots are alive and waiting
            // (again, after a stop); later looks only while they still are.
            state.store.workers_idle(&workers).await?;
            first = false;
        }
        let now = tokio::time::Instant::now();
        let stopping = state
            .shutting_down
            .load(std::sync::atomic::Ordering::SeqCst);
        if now >= deadline || stopping {
            return Ok(Vec::new());
        }
        // Retry delays and lease expiries free jobs without a notification:
        // look again at least every second.
        let nap = (deadline - now).min(Duration::from_secs(1));
        let client_gone = async {
            match gone.as_mut() {
                Some(g) => g.wait().await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            _ = tokio::time::timeout(nap, notified) => {}
            () = client_gone => {}
        }
    }
}

#[utoipa::path(post, path = "/v1/jobs/{id}/heartbeat", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = HeartbeatRequest,
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "Lease extended", body = HeartbeatReply), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn heartbeat(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<HeartbeatRequest>,
) -> ApiResult<Json<HeartbeatReply>> {
    let beat = state
        .store
        .heartbeat(id, &req.token, req.progress, &state.policy)
        .await?;
    // Progress inside a job (a sample's poses, a fit's steps) reaches the
    // bake's listeners, whose views add running jobs' progress.
    if beat.moved {
        state.publish(&beat.bake);
    }
    Ok(Json(HeartbeatReply {
        stop: beat.stop,
        bake_state: Some(beat.bake.state),
    }))
}

#[utoipa::path(post, path = "/v1/jobs/{id}/checkpoint", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = CheckpointRequest,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Saved"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn checkpoint(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<CheckpointRequest>,
) -> ApiResult<StatusCode> {
    stored(&*state.blobs, &req.checkpoint.blob).await?;
    state
        .store
        .checkpoint(id, &req.token, &req.checkpoint)
        .await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `Ok` when `digest` names a stored blob, else 400 `missing_blob` (or
/// the store's own error).
async fn stored(blobs: &dyn crate::blobs::Blobs, digest: &str) -> ApiResult<()> {
    crate::blobs::check_digest(digest)?;
    if blobs.len(digest).await?.is_none() {
        return Err(ApiError::bad(
            "missing_blob",
            format!("blob {digest} was not uploaded"),
        ));
    }
    Ok(())
}

#[utoipa::path(post, path = "/v1/jobs/{id}/complete", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = CompleteRequest,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Completed (also when this lease completed it already: a completion sent again after its answer was lost is counted once)"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn complete(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<CompleteRequest>,
) -> ApiResult<StatusCode> {
    let item = JobCompletion {
        job: id,
        token: req.token,
        completion: req.completion,
    };
    record(&state, vec![item])
        .await?
        .pop()
        .unwrap_or_else(|| Err(ApiError::Internal(format!("job {id}: no answer"))))?;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(post, path = "/v1/jobs/completions", tag = "worker protocol", request_body = CompleteManyRequest,
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "One result per completion: recorded (or recorded before under the same lease: a completion sent again is counted once), or the problem that refused it", body = CompleteManyReply), Refusals))]
pub(crate) async fn complete_many(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    headers: axum::http::HeaderMap,
    Body(req): Body<CompleteManyRequest>,
) -> ApiResult<Json<CompleteManyReply>> {
    if req.completions.is_empty() || req.completions.len() > MAX_BATCH {
        return Err(ApiError::bad(
            "bad_completions",
            format!("a completions request carries 1 to {MAX_BATCH} completions"),
        ));
    }
    let jobs: Vec<i64> = req.completions.iter().map(|c| c.job).collect();
    let results = jobs
        .into_iter()
        .zip(record(&state, req.completions).await?)
        .map(|(job, answer)| CompletionResult {
            job,
            problem: answer.err().map(|e| match e {
                // Logged with the request's id, as a whole request's
                // internal error is (app::log_failures), and the item says
                // which.
                ApiError::Internal(what) => ApiError::log_internal(
                    headers.get("x-request-id"),
                    format_args!("POST /v1/jobs/completions, job {job}"),
                    &what,
                ),
                refused => refused.problem(),
            }),
        })
        .collect();
    Ok(Json(CompleteManyReply { results }))
}

/// Records completions in one store transaction, each as `complete`
/// would: one answer per item, in order. Outputs must be stored before a
/// completion names them; each digest is looked up once, all at once, and
/// a missing one refuses only the items that name it. The outer error
/// (a blob store or database that does not answer: 503) fails them all,
/// and the worker sends them again.
async fn record(state: &AppState, items: Vec<JobCompletion>) -> ApiResult<Vec<ApiResult<()>>> {
    let digests: BTreeSet<String> = items
        .iter()
        .flat_map(|c| c.completion.outputs.iter().map(|o| o.digest.clone()))
        .collect();
    let mut lookups = tokio::task::JoinSet::new();
    for digest in digests {
        let blobs = state.blobs.clone();
        lookups.spawn(async move {
            let found = stored(&*blobs, &digest).await;
            (digest, found)
        });
    }
    let mut missing: BTreeMap<String, ApiError> = BTreeMap::new();
    while let Some(joined) = lookups.join_next().await {
        let (digest, found) = joined.map_err(|e| ApiError::Internal(e.to_string()))?;
        match found {
            Ok(()) => {}
            Err(e @ ApiError::Unavailable(..)) => return Err(e),
            Err(e) => {
                missing.insert(digest, e);
            }
        }
    }
    let refusals: Vec<Option<ApiError>> = items
        .iter()
        .map(|c| {
            c.completion
                .outputs
                .iter()
                .find_map(|o| missing.get(&o.digest).cloned())
        })
        .collect();
    let ready: Vec<JobCompletion> = items
        .into_iter()
        .zip(&refusals)
        .filter_map(|(c, refused)| refused.is_none().then_some(c))
        .collect();
    let mut recorded = state.store.complete_many(&ready).await?.into_iter();
    let mut announced = BTreeSet::new();
    Ok(refusals
        .into_iter()
        .map(|refused| {
            if let Some(e) = refused {
                return Err(e);
            }
            match recorded.next() {
                Some(Ok(bake)) => {
                    // Every answer for a bake is its row after the batch:
                    // announce it once.
                    if announced.insert(bake.id) {
                        state.announce(&bake);
                    }
                    Ok(())
                }
                Some(Err(e)) => Err(ApiError::from(e)),
                None => Err(ApiError::Internal("the store gave no answer".into())),
            }
        })
        .collect())
}

#[utoipa::path(post, path = "/v1/jobs/{id}/fail", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = FailRequest,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Recorded"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn fail(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<FailRequest>,
) -> ApiResult<StatusCode> {
    let error: String = req.error.chars().take(4000).collect();
    let bake = state
        .store
        .fail(id, &req.token, &error, req.retryable, &state.policy)
        .await?;
    state.announce(&bake);
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(post, path = "/v1/jobs/{id}/release", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = TokenRequest,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Given back"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn release(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<TokenRequest>,
) -> ApiResult<StatusCode> {
    state.store.release(id, &req.token).await?;
    state.jobs_ready.notify_waiters();
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(get, path = "/v1/blobs/{digest}", tag = "worker protocol", params(("digest" = Digest, Path, description = "sha256 of the bytes")),
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "The bytes", content_type = "application/octet-stream", body = crate::routes::uploads::FileBytes), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn get_blob(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(digest): ApiPath<String>,
) -> ApiResult<Response> {
    let bytes = state
        .read_blob(&digest, None)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no blob {digest}")))?;
    Ok(bytes.into_response())
}

#[utoipa::path(put, path = "/v1/blobs/{digest}", tag = "worker protocol", params(("digest" = Digest, Path, description = "sha256 of the bytes")), request_body(content = crate::routes::uploads::FileBytes, content_type = "application/octet-stream"),
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Stored"), (status = 413, description = "Body over the limit", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn put_blob(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(digest): ApiPath<String>,
    body: Result<Bytes, axum::extract::rejection::BytesRejection>,
) -> ApiResult<StatusCode> {
    let body = body.map_err(|_| ApiError::TooLarge(state.limits.max_body_bytes))?;
    state.blobs.put(&digest, &body).await?;
    Ok(StatusCode::NO_CONTENT)
}
