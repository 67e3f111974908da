//! Workers, tokens, health and metrics.

use aobake_api::schema::Refusals;
use aobake_api::{NewToken, NewTokenRequest, TokenView, Whoami};
use axum::{
    Json, Router,
    extract::State,
    http::{StatusCode, header},
    response::{IntoResponse, Response},
    routing::{get, post},
};

use crate::{
    auth::{Admin, Need, Read, new_token, token_hash},
    error::{ApiError, ApiResult, BLOBS_RETRY_SECS, Outage, Problem},
    extract::{ApiPath, Body},
    state::AppState,
    store::WorkerRow,
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/workers", get(workers))
        .route("/v1/whoami", get(whoami))
        .route("/v1/tokens", post(create_token).get(tokens))
        .route("/v1/tokens/{id}", axum::routing::delete(revoke_token))
        .route("/healthz", get(healthz))
        .route("/v1/openapi.yaml", get(openapi))
        .route("/readyz", get(ready))
        .route("/metrics", get(metrics))
}

#[utoipa::path(get, path = "/v1/workers", tag = "system",
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Workers, most recently seen first", body = Vec<WorkerRow>), Refusals))]
pub(crate) async fn workers(
    State(state): State<AppState>,
    _caller: Need<Read>,
) -> ApiResult<Json<Vec<WorkerRow>>> {
    Ok(Json(state.store.workers(state.policy.lease_ms).await?))
}

#[utoipa::path(get, path = "/v1/whoami", tag = "system",
    security(("bearer" = [])),
    responses((status = 200, description = "The caller's token name and scopes: what a dashboard may offer", body = Whoami), Refusals))]
pub(crate) async fn whoami(caller: crate::auth::Caller) -> Json<Whoami> {
    Json(Whoami {
        name: caller.name,
        scopes: caller.scopes.iter().map(|s| s.name().to_owned()).collect(),
    })
}

#[utoipa::path(post, path = "/v1/tokens", tag = "system", request_body = NewTokenRequest,
    security(("bearer" = ["admin"])),
    responses((status = 201, description = "The token, shown once", body = NewToken), Refusals))]
pub(crate) async fn create_token(
    State(state): State<AppState>,
    _caller: Need<Admin>,
    Body(req): Body<NewTokenRequest>,
) -> ApiResult<(StatusCode, Json<NewToken>)> {
    if req.scopes.is_empty() {
        return Err(ApiError::bad(
            "bad_scope",
            "a token needs at least one scope",
        ));
    }
    if let Some(bad) = req
        .scopes
        .iter()
        .find(|s| crate::auth::Scope::parse(s).is_none())
    {
        return Err(ApiError::bad(
            "bad_scope",
            format!("unknown scope {bad:?}; the scopes are read, submit, worker, admin"),
        ));
    }
    const LONGEST: u64 = aobake_api::MAX_TOKEN_SECS;
    let expires_at = match req.expires_in_secs {
        None => None,
        Some(s @ 1..=LONGEST) => Some(crate::auth::now_ms() + 1000 * s as i64),
        Some(s) => {
            return Err(ApiError::bad(
                "bad_expiry",
                format!("expires_in_secs is 1 to {LONGEST} (ten years), not {s}"),
            ));
        }
    };
    let token = new_token();
    state
        .store
        .create_token_until(&token_hash(&token), &req.name, &req.scopes, expires_at)
        .await?;
    Ok((
        StatusCode::CREATED,
        Json(NewToken {
            token,
            name: req.name,
            scopes: req.scopes,
            expires_at,
        }),
    ))
}

#[utoipa::path(get, path = "/v1/tokens", tag = "system",
    security(("bearer" = ["admin"])),
    responses((status = 200, description = "Every token, newest first: its id (the sha256 of the secret, which is not stored), name, scopes, age, expiry (an expired one is listed until revoked) and last use", body = Vec<TokenView>), Refusals))]
pub(crate) async fn tokens(
    State(state): State<AppState>,
    caller: Need<Admin>,
) -> ApiResult<Json<Vec<TokenView>>> {
    let rows = state.store.tokens().await?;
    Ok(Json(
        rows.into_iter()
            .map(|(hash, row)| TokenView {
                current: hash == caller.0.hash,
                id: hash,
                name: row.name,
                scopes: row.scopes,
                created_at: row.created_at,
                expires_at: row.expires_at,
                last_used_at: row.last_used_at,
            })
            .collect(),
    ))
}

#[utoipa::path(delete, path = "/v1/tokens/{id}", tag = "system",
    params(("id" = String, Path, description = "The token's id, as `GET /v1/tokens` lists it")),
    security(("bearer" = ["admin"])),
    responses((status = 204, description = "Revoked: refused from its next request on"),
        (status = 400, description = "Not a token id", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such token", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The token of this request: revoke it with another admin token", body = Problem, content_type = "application/problem+json"),
        Refusals))]
pub(crate) async fn revoke_token(
    State(state): State<AppState>,
    caller: Need<Admin>,
    ApiPath(id): ApiPath<String>,
) -> ApiResult<StatusCode> {
    if crate::blobs::check_digest(&id).is_err() {
        return Err(ApiError::bad(
            "bad_token_id",
            "a token id is 64 lower-case hex digits, as GET /v1/tokens lists it",
        ));
    }
    if id == caller.0.hash {
        return Err(ApiError::Conflict(
            "this is the token of this request: revoke it with another admin token, so that one is left".into(),
        ));
    }
    if !state.store.delete_token(&id, true).await? {
        return Err(ApiError::NotFound(format!("no token {id}")));
    }
    Ok(StatusCode::NO_CONTENT)
}

/// This API's OpenAPI document (no token: client generators fetch it;
/// the same as `api-spec/openapi.yaml` and `aobake openapi`).
#[utoipa::path(get, path = "/v1/openapi.yaml", tag = "system", responses((status = 200, description = "The OpenAPI 3.1 document of this API", content_type = "application/yaml", body = String)))]
pub(crate) async fn openapi() -> impl IntoResponse {
    static SPEC: std::sync::LazyLock<String> = std::sync::LazyLock::new(crate::openapi::yaml);
    ([(header::CONTENT_TYPE, "application/yaml")], SPEC.as_str())
}

/// Liveness: the process answers (no token: load balancers call it).
#[utoipa::path(get, path = "/healthz", tag = "system", responses((status = 200, description = "Alive", body = String)))]
pub(crate) async fn healthz() -> &'static str {
    "ok"
}

/// Readiness: the database answers (no token).
#[utoipa::path(get, path = "/readyz", tag = "system", responses((status = 200, description = "Ready", body = String), (status = 503, description = "The database or the blob store does not answer (the detail names which)", body = Problem, content_type = "application/problem+json", headers(("Retry-After" = u64, description = "Seconds to wait before looking again")))))]
pub(crate) async fn ready(State(state): State<AppState>) -> ApiResult<&'static str> {
    state.store.ping().await?;
    // The blob store answers its probe (a bucket's listing), within a
    // probe's patience: the S3 client's own retries can take longer.
    match tokio::time::timeout(BLOBS_PROBE, state.blobs.probe()).await {
        Ok(Ok(())) => {}
        // Not ready, whatever the store answered (a bucket that is not
        // there, settings it refuses): the log says what.
        Ok(Err(e)) => {
            log_line!("error: the blob store fails the readiness probe: {e}");
            return Err(ApiError::Unavailable(
                Outage::of_blobs(&e),
                BLOBS_RETRY_SECS,
            ));
        }
        Err(_) => {
            log_line!(
                "error: the blob store did not answer the readiness probe in {BLOBS_PROBE:?}"
            );
            return Err(ApiError::Unavailable(Outage::Blobs, BLOBS_RETRY_SECS));
        }
    };
    Ok("ready")
}

/// How long the readiness probe waits for the blob store.
const BLOBS_PROBE: std::time::Duration = std::time::Duration::from_secs(3);

#[utoipa::path(get, path = "/metrics", tag = "system",
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Prometheus text: jobs by state, lease expiries, request latencies", content_type = "application/openmetrics-text", body = String), Refusals))]
pub(crate) async fn metrics(
    State(state): State<AppState>,
    _caller: Need<Read>,
) -> ApiResult<Response> {
    let (jobs, expiries) = state.store.queue_stats().await?;
    let out = state.metrics.encode(&jobs, expiries)?;
    Ok((
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        out,
    )
        .into_response())
}
