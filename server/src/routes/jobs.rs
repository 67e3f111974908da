//! The worker protocol: lease (long-polled), heartbeat, checkpoint,
//! complete, fail and release, each but lease checked against the job's
//! current lease token (a stale one gets 409), and the blobs workers read
//! and write.

use aobake_api::schema::{Digest, Refusals};
use aobake_api::{
    CheckpointRequest, CompleteRequest, FailRequest, HeartbeatReply, HeartbeatRequest,
    LeaseRequest, TokenRequest,
};
use std::time::Duration;

use axum::{
    Json, Router,
    body::Bytes,
    extract::State,
    http::StatusCode,
    response::{IntoResponse, Response},
    routing::{get, post},
};

use crate::{
    auth::{Need, Worker},
    error::{ApiError, ApiResult, Problem},
    extract::{ApiPath, Body},
    state::AppState,
    store::Lease,
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/jobs/lease", post(lease))
        .route("/v1/jobs/{id}/heartbeat", post(heartbeat))
        .route("/v1/jobs/{id}/checkpoint", post(checkpoint))
        .route("/v1/jobs/{id}/complete", post(complete))
        .route("/v1/jobs/{id}/fail", post(fail))
        .route("/v1/jobs/{id}/release", post(release))
        .route("/v1/blobs/{digest}", get(get_blob).put(put_blob))
}

#[utoipa::path(post, path = "/v1/jobs/lease", tag = "worker protocol", request_body = LeaseRequest,
    security(("bearer" = ["worker"])),
    responses((status = 200, description = "A leased job", body = Lease), (status = 204, description = "No job within wait_secs"), Refusals))]
pub(crate) async fn lease(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    Body(req): Body<LeaseRequest>,
) -> ApiResult<Response> {
    if req.worker.is_empty() || req.worker.len() > 200 {
        return Err(ApiError::bad(
            "bad_worker",
            "worker ids are 1 to 200 characters",
        ));
    }
    if let Some(tracer) = &req.tracer {
        if tracer.is_empty() || tracer.len() > 200 {
            return Err(ApiError::bad(
                "bad_tracer",
                "a worker's tracer is 1 to 200 characters",
            ));
        }
        state.store.worker_tracer(&req.worker, tracer).await?;
    }
    let deadline = tokio::time::Instant::now() + Duration::from_secs(req.wait_secs.min(60));
    loop {
        // Register interest before looking, so a job made available between
        // the look and the wait still wakes us.
        let notified = state.jobs_ready.notified();
        if let Some(lease) = state.store.lease(&req.worker, &state.policy).await? {
            if let Some(bake) = state.store.bake(lease.bake.id).await? {
                state.announce(&bake);
            }
            return Ok(Json(lease).into_response());
        }
        state.store.worker_seen(&req.worker, "idle", None).await?;
        let now = tokio::time::Instant::now();
        let stopping = state
            .shutting_down
            .load(std::sync::atomic::Ordering::SeqCst);
        if now >= deadline || stopping {
            return Ok(StatusCode::NO_CONTENT.into_response());
        }
        // Retry delays and lease expiries free jobs without a notification:
        // look again at least every second.
        let nap = (deadline - now).min(Duration::from_secs(1));
        let _ = tokio::time::timeout(nap, notified).await;
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
    Ok(Json(HeartbeatReply { stop: beat.stop }))
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
    require_blob(&state, &req.checkpoint.blob).await?;
    state
        .store
        .checkpoint(id, &req.token, &req.checkpoint)
        .await?;
    Ok(StatusCode::NO_CONTENT)
}

async fn require_blob(state: &AppState, digest: &str) -> ApiResult<()> {
    crate::blobs::check_digest(digest)?;
    if state.blobs.len(digest).await?.is_none() {
        return Err(ApiError::bad(
            "missing_blob",
            format!("blob {digest} was not uploaded"),
        ));
    }
    Ok(())
}

#[utoipa::path(post, path = "/v1/jobs/{id}/complete", tag = "worker protocol", params(("id" = i64, Path, description = "Job id")), request_body = CompleteRequest,
    security(("bearer" = ["worker"])),
    responses((status = 204, description = "Completed"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn complete(
    State(state): State<AppState>,
    _caller: Need<Worker>,
    ApiPath(id): ApiPath<i64>,
    Body(req): Body<CompleteRequest>,
) -> ApiResult<StatusCode> {
    for o in &req.completion.outputs {
        require_blob(&state, &o.digest).await?;
    }
    let bake = state
        .store
        .complete(id, &req.token, &req.completion)
        .await?;
    state.announce(&bake);
    Ok(StatusCode::NO_CONTENT)
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
    responses((status = 200, description = "The bytes", content_type = "application/octet-stream", body = Vec<u8>), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
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

#[utoipa::path(put, path = "/v1/blobs/{digest}", tag = "worker protocol", params(("digest" = Digest, Path, description = "sha256 of the bytes")), request_body(content = Vec<u8>, content_type = "application/octet-stream"),
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
