//! Workers, tokens, health and metrics.

use aobake_api::schema::Refusals;
use aobake_api::{NewToken, NewTokenRequest, Whoami};
use axum::{
    Json, Router,
    extract::State,
    http::{StatusCode, header},
    response::{IntoResponse, Response},
    routing::{get, post},
};

use crate::{
    auth::{Admin, Need, Read, new_token, token_hash},
    error::{ApiError, ApiResult, Problem},
    extract::Body,
    state::AppState,
    store::WorkerRow,
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/workers", get(workers))
        .route("/v1/whoami", get(whoami))
        .route("/v1/tokens", post(create_token))
        .route("/healthz", get(healthz))
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
    Ok(Json(state.store.workers().await?))
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
    let token = new_token();
    state
        .store
        .create_token(&token_hash(&token), &req.name, &req.scopes)
        .await?;
    Ok((
        StatusCode::CREATED,
        Json(NewToken {
            token,
            name: req.name,
            scopes: req.scopes,
        }),
    ))
}

/// Liveness: the process answers (no token: load balancers call it).
#[utoipa::path(get, path = "/healthz", tag = "system", responses((status = 200, description = "Alive", body = String)))]
pub(crate) async fn healthz() -> &'static str {
    "ok"
}

/// Readiness: the database answers (no token).
#[utoipa::path(get, path = "/readyz", tag = "system", responses((status = 200, description = "Ready", body = String), (status = 503, description = "The database does not answer (Retry-After says when to look again)", body = Problem, content_type = "application/problem+json")))]
pub(crate) async fn ready(State(state): State<AppState>) -> ApiResult<&'static str> {
    state.store.ping().await?;
    Ok("ready")
}

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
