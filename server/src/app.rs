//! The application: shared state, the router of every route, and the
//! layers around it (request ids, body limits, timeouts, latency metrics).
//! [`app`] builds it without a socket, so tests call it directly.

use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::{
    Router,
    extract::{DefaultBodyLimit, Request, State},
    http::HeaderName,
    middleware::{self, Next},
    response::Response,
};
use governor::{DefaultKeyedRateLimiter, Quota, RateLimiter};
use prometheus_client::{
    encoding::EncodeLabelSet,
    metrics::{counter::Counter, family::Family, gauge::Gauge, histogram::Histogram},
    registry::Registry,
};
use tokio::sync::{Notify, broadcast};
use tower_http::{
    request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer},
    timeout::TimeoutLayer,
};

use crate::{
    blobs::Blobs,
    error::ApiError,
    routes,
    store::{QueuePolicy, Store},
};

/// What the server enforces besides the import limits.
#[derive(Debug, Clone, Copy)]
pub struct ServerLimits {
    /// Largest request body (uploads, blobs), checked while it streams.
    pub max_body_bytes: u64,
    /// Most ray-vertex pairs one bake may trace.
    pub max_bake_work: u128,
    /// Requests per second per token (bursts of twice that).
    pub requests_per_second: u32,
    /// Longest a request may take (long polls excepted).
    pub request_timeout: Duration,
}

impl Default for ServerLimits {
    fn default() -> Self {
        Self {
            max_body_bytes: 256 << 20,
            // About four hours of tracing on a 2-core machine (14 Mrays/s):
            // CesiumMan's default bake is 2.6e8.
            max_bake_work: 200_000_000_000,
            requests_per_second: 200,
            request_timeout: Duration::from_secs(120),
        }
    }
}

/// A change a browser or a waiting client hears about.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BakeEvent {
    /// The bake.
    pub id: i64,
    /// Its state.
    pub state: crate::store::BakeState,
    /// Units done.
    pub done: i64,
    /// Units in all.
    pub total: i64,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RouteLabels {
    method: String,
    route: String,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabels {
    state: &'static str,
}

/// The service's metrics: request latencies, jobs by state, lease
/// expiries.
#[derive(Debug)]
pub struct Metrics {
    registry: std::sync::Mutex<Registry>,
    latency: Family<RouteLabels, Histogram>,
    jobs: Family<StateLabels, Gauge>,
    lease_expiries: Counter,
}

impl Metrics {
    fn new() -> Self {
        let latency = Family::<RouteLabels, Histogram>::new_with_constructor(|| {
            Histogram::new([
                0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0,
            ])
        });
        let mut registry = Registry::default();
        registry.register(
            "aobake_request_seconds",
            "HTTP request latency by method and route",
            latency.clone(),
        );
        let jobs = Family::<StateLabels, Gauge>::default();
        registry.register("aobake_jobs", "Jobs by state", jobs.clone());
        let lease_expiries = Counter::default();
        registry.register(
            "aobake_lease_expiries",
            "Leases that expired without a heartbeat",
            lease_expiries.clone(),
        );
        Self {
            registry: std::sync::Mutex::new(registry),
            latency,
            jobs,
            lease_expiries,
        }
    }

    /// The OpenMetrics text, with the queue's figures as the store counts
    /// them now.
    pub fn encode(
        &self,
        jobs: &[(crate::store::JobState, i64)],
        lease_expiries: i64,
    ) -> Result<String, ApiError> {
        for s in crate::store::JobState::ALL {
            let n = jobs.iter().find(|(x, _)| *x == s).map_or(0, |(_, n)| *n);
            self.jobs
                .get_or_create(&StateLabels { state: s.as_str() })
                .set(n);
        }
        // The store keeps the total; the counter catches up with it.
        let seen = self.lease_expiries.get();
        self.lease_expiries.inc_by(
            u64::try_from(lease_expiries)
                .unwrap_or(0)
                .saturating_sub(seen),
        );
        let registry = self
            .registry
            .lock()
            .map_err(|_| ApiError::Internal("metrics lock poisoned".into()))?;
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &registry)
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        Ok(out)
    }
}

/// Everything a handler may reach.
#[derive(Clone, Debug)]
pub struct AppState {
    /// Metadata and queue.
    pub store: Arc<dyn Store>,
    /// Bytes.
    pub blobs: Arc<dyn Blobs>,
    /// Lease and retry behaviour.
    pub policy: QueuePolicy,
    /// Limits.
    pub limits: ServerLimits,
    /// Import limits.
    pub import_limits: aobake_core::Limits,
    /// Woken when jobs may have become available.
    pub jobs_ready: Arc<Notify>,
    /// Set when the server shuts down: long polls answer at once.
    pub shutting_down: Arc<std::sync::atomic::AtomicBool>,
    /// Bake state and progress changes.
    pub events: broadcast::Sender<BakeEvent>,
    /// Per-token request rate.
    pub limiter: Arc<Limiter>,
    /// Whole blobs read into memory at once (each may be as large as the
    /// body limit): a bound on what concurrent downloads can allocate.
    pub blob_reads: Arc<tokio::sync::Semaphore>,
    /// Request metrics.
    pub metrics: Arc<Metrics>,
}

/// A rate limiter keyed by token hash.
#[derive(Debug)]
pub struct Limiter(DefaultKeyedRateLimiter<String>);

impl Limiter {
    fn new(per_second: u32) -> Self {
        let rate = NonZeroU32::new(per_second.max(1)).expect("positive");
        let burst = NonZeroU32::new(per_second.max(1).saturating_mul(2)).expect("positive");
        Self(RateLimiter::keyed(
            Quota::per_second(rate).allow_burst(burst),
        ))
    }

    /// 429 with the seconds to wait when `key` is over its rate.
    pub fn check(&self, key: &str) -> Result<(), ApiError> {
        self.0.check_key(&key.to_owned()).map_err(|not_until| {
            let wait = not_until.wait_time_from(governor::clock::Clock::now(
                &governor::clock::DefaultClock::default(),
            ));
            ApiError::RateLimited(wait.as_secs().max(1))
        })
    }
}

impl AppState {
    /// State over a store and a blob store.
    pub fn new(
        store: Arc<dyn Store>,
        blobs: Arc<dyn Blobs>,
        policy: QueuePolicy,
        limits: ServerLimits,
    ) -> Self {
        Self {
            store,
            blobs,
            policy,
            limits,
            import_limits: aobake_core::Limits::default(),
            jobs_ready: Arc::new(Notify::new()),
            shutting_down: Arc::default(),
            events: broadcast::channel(1024).0,
            limiter: Arc::new(Limiter::new(limits.requests_per_second)),
            blob_reads: Arc::new(tokio::sync::Semaphore::new(8)),
            metrics: Arc::new(Metrics::new()),
        }
    }

    /// Bytes `range` (or all) of a blob, read into memory under the bound
    /// on concurrent whole-blob reads.
    pub async fn read_blob(
        &self,
        digest: &str,
        range: Option<(u64, u64)>,
    ) -> Result<Option<Vec<u8>>, ApiError> {
        let _permit = self
            .blob_reads
            .acquire()
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        Ok(match range {
            Some((start, end)) => self.blobs.get_range(digest, start, end).await?,
            None => self.blobs.get(digest).await?,
        })
    }

    /// Ends every long poll (they answer 204), so a graceful shutdown does
    /// not wait for them.
    pub fn shut_down(&self) {
        self.shutting_down
            .store(true, std::sync::atomic::Ordering::SeqCst);
        self.jobs_ready.notify_waiters();
    }

    /// Tells listeners about a bake's state and wakes waiting workers.
    pub fn announce(&self, bake: &crate::store::BakeRow) {
        self.publish(bake);
        self.jobs_ready.notify_waiters();
    }

    /// Tells listeners about a bake (progress inside a running job: no
    /// job became ready, so no worker is woken).
    pub fn publish(&self, bake: &crate::store::BakeRow) {
        let _ = self.events.send(BakeEvent {
            id: bake.id,
            state: bake.state,
            done: bake.done_work,
            total: bake.total_work,
        });
    }
}

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
/// accepted request must finish what it started.
async fn to_completion(req: Request, next: Next) -> Response {
    match tokio::spawn(next.run(req)).await {
        Ok(res) => res,
        Err(e) => axum::response::IntoResponse::into_response(ApiError::Internal(format!(
            "the handler failed: {e}"
        ))),
    }
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
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid))
        .with_state(state)
}
