//! The application: the router of every route and the layers around it
//! (request ids, body limits, timeouts, latency metrics) over the shared
//! [`AppState`]. [`app`] builds it without a socket, so tests call it
//! directly.

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::{
    Router,
    extract::{DefaultBodyLimit, Request, State},
    http::HeaderName,
    middleware::{self, Next},
    response::Response,
};
use tower_http::{
    request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer},
    timeout::TimeoutLayer,
};

use crate::{
    error::{ApiError, InternalFailure},
    routes,
    state::{AppState, Metrics, RouteLabels},
};

async fn record_latency(
    State(metrics): State<Arc<Metrics>>,
    matched: Option<axum::extract::MatchedPath>,
    req: Request,
    next: Next,
) -> Response {
    let started = Instant::now();
    let labels = RouteLabels {
        method: req.method().to_string(),
        route: matched.map_or_else(|| "unmatched".to_owned(), |m| m.as_str().to_owned()),
    };
    let res = next.run(req).await;
    metrics
        .latency
        .get_or_create(&labels)
        .observe(started.elapsed().as_secs_f64());
    res
}

/// Refuses a body whose declared length is over the limit before reading
/// any of it; bodies without a declared length are cut off by the limit as
/// they stream.
async fn declared_length(State(limit): State<u64>, req: Request, next: Next) -> Response {
    let declared = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit) {
        return axum::response::IntoResponse::into_response(ApiError::TooLarge(limit));
    }
    next.run(req).await
}

/// Runs the handler on its own task, so that a client that disconnects
/// (or a timeout) cannot cancel it half-way: a store operation cancelled
/// inside `BEGIN` would leave its pooled connection in a transaction
/// (sqlx's `begin` is not cancel-safe, transact-rs/sqlx#4385), and an
/// accepted request must finish what it started. A handler that only
/// waits (a long poll) learns from [`ClientGone`] that nobody waits for
/// its answer any more.
async fn to_completion(mut req: Request, next: Next) -> Response {
    // Dropped with this future: when the client's connection closes, or
    // when the handler has answered.
    let (present, gone) = tokio::sync::watch::channel(());
    req.extensions_mut().insert(ClientGone(gone));
    let answer = tokio::spawn(next.run(req)).await;
    drop(present);
    match answer {
        Ok(res) => res,
        Err(e) => axum::response::IntoResponse::into_response(ApiError::Internal(format!(
            "the handler failed: {e}"
        ))),
    }
}

/// Whether the client that sent a request has gone: its connection closed
/// before the answer (hyper then drops the request's future, and with it
/// [`to_completion`]'s side of this channel).
#[derive(Debug, Clone)]
pub struct ClientGone(tokio::sync::watch::Receiver<()>);

impl ClientGone {
    /// Whether the client has gone.
    pub fn is_gone(&self) -> bool {
        self.0.has_changed().is_err()
    }

    /// Resolves when the client has gone.
    pub async fn wait(&mut self) {
        while self.0.changed().await.is_ok() {}
    }
}

/// Logs an internal error with the request's id, method and path, and
/// answers with that id in the detail, so a user's 500 leads to its log
/// line on whichever server of a fleet answered it.
async fn log_failures(req: Request, next: Next) -> Response {
    // Kept for a failure (cheap copies: every request passes here).
    let id = req.headers().get("x-request-id").cloned();
    let (method, uri) = (req.method().clone(), req.uri().clone());
    let res = next.run(req).await;
    let Some(InternalFailure(what)) = res.extensions().get::<InternalFailure>().cloned() else {
        return res;
    };
    let problem =
        ApiError::log_internal(id.as_ref(), format_args!("{method} {}", uri.path()), &what);
    let (mut parts, _) = res.into_parts();
    parts.headers.remove(axum::http::header::CONTENT_LENGTH);
    let body = serde_json::to_vec(&problem).unwrap_or_default();
    Response::from_parts(parts, axum::body::Body::from(body))
}

/// 404 for a path no route serves, as problem+json like every error.
async fn no_route(uri: axum::http::Uri) -> ApiError {
    ApiError::NotFound(format!("no route for {}", uri.path()))
}

/// 405 for a route that exists under other methods, with `Allow` kept.
async fn wrong_method(method: axum::http::Method, uri: axum::http::Uri) -> ApiError {
    ApiError::MethodNotAllowed(format!("{} does not take {method}", uri.path()))
}

/// Every route, with request ids, limits and metrics.
pub fn app(state: AppState) -> Router {
    let request_id = HeaderName::from_static("x-request-id");
    let limits = state.limits;
    let metrics = state.metrics.clone();
    Router::new()
        .merge(routes::router())
        .merge(crate::dashboard::router())
        .fallback(no_route)
        .method_not_allowed_fallback(wrong_method)
        .layer(middleware::from_fn(to_completion))
        .layer(middleware::from_fn_with_state(metrics, record_latency))
        .layer(DefaultBodyLimit::max(limits.max_body_bytes as usize))
        .layer(middleware::from_fn_with_state(
            limits.max_body_bytes,
            declared_length,
        ))
        .layer(TimeoutLayer::with_status_code(
            axum::http::StatusCode::REQUEST_TIMEOUT,
            limits.request_timeout + Duration::from_secs(60),
        ))
        .layer(middleware::from_fn(log_failures))
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid))
        .with_state(state)
}
