//! The server's shared state: the store, blobs, limits, the rate limiter,
//! metrics and the bake-event broadcast every handler reads
//! ([`AppState`]); the router that serves it is in [`crate::app`].

use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::Duration;

use governor::{DefaultKeyedRateLimiter, Quota, RateLimiter};
use prometheus_client::{
    encoding::EncodeLabelSet,
    metrics::{counter::Counter, family::Family, gauge::Gauge, histogram::Histogram},
    registry::Registry,
};
use tokio::sync::{Notify, broadcast};

use crate::{
    blobs::Blobs,
    error::ApiError,
    store::{QueuePolicy, Store},
};

/// What the server enforces besides the import limits.
#[derive(Debug, Clone, Copy)]
pub struct ServerLimits {
    /// Largest request body (uploads, blobs), checked while it streams.
    pub max_body_bytes: u64,
    /// Most ray-vertex pairs one bake may trace.
    pub max_bake_work: u128,
    /// Most bytes of uploads (the character and its clip files) one bake
    /// may use: each import of the bake (its submit, every worker's jobs)
    /// holds them all in memory.
    pub max_bake_input_bytes: u64,
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
            max_bake_input_bytes: 1 << 30,
            requests_per_second: 200,
            request_timeout: Duration::from_secs(120),
        }
    }
}

/// A change a browser or a waiting client hears about.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BakeEvent {
    /// The bake.
    pub id: i64,
    /// Its state.
    pub state: crate::store::BakeState,
    /// Units done, the running jobs' progress included: what the bake's
    /// view says (`progress.done`).
    pub done: i64,
    /// Units in all.
    pub total: i64,
    /// Of `done`, the units being done again (the view's
    /// `progress.redo`).
    #[serde(default)]
    pub redo: i64,
}

impl BakeEvent {
    /// The event that tells of `bake` as it is.
    pub fn of(bake: &crate::store::BakeRow) -> Self {
        Self {
            id: bake.id,
            state: bake.state,
            done: progress_done(bake),
            total: bake.total_work,
            redo: bake.redo_work,
        }
    }
}

/// A bake's units done: its finished jobs' work and how far its other
/// jobs got (the furthest attempt of each), so it only moves forward.
pub fn progress_done(bake: &crate::store::BakeRow) -> i64 {
    (bake.done_work + bake.running_work).min(bake.total_work)
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub(crate) struct RouteLabels {
    pub(crate) method: String,
    pub(crate) route: String,
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
    pub(crate) latency: Family<RouteLabels, Histogram>,
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
    /// Bake state and progress changes, as this server's listeners hear
    /// them.
    pub events: broadcast::Sender<BakeEvent>,
    /// Where several servers share the store (PostgreSQL): publishes an
    /// event to every server's `events`, this one's included ([`AppState::share_events`]).
    shared_events: Option<tokio::sync::mpsc::UnboundedSender<BakeEvent>>,
    /// Per-token request rate.
    pub limiter: Arc<Limiter>,
    /// Whole blobs read into memory at once (each may be as large as the
    /// body limit): a bound on what concurrent downloads can allocate.
    pub blob_reads: Arc<tokio::sync::Semaphore>,
    /// Imports of untrusted uploads running at once ([`AppState::import`]).
    pub imports: Arc<tokio::sync::Semaphore>,
    /// Request metrics.
    pub metrics: Arc<Metrics>,
    /// When this server last recorded each token's use (ms since the
    /// epoch, by hash): a write at most once a minute per token.
    pub token_uses: Arc<std::sync::Mutex<std::collections::HashMap<String, i64>>>,
    /// How new bakes are cut into jobs.
    pub graph: aobake_core::bake::GraphOptions,
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
            shared_events: None,
            limiter: Arc::new(Limiter::new(limits.requests_per_second)),
            blob_reads: Arc::new(tokio::sync::Semaphore::new(8)),
            imports: Arc::new(tokio::sync::Semaphore::new(
                std::thread::available_parallelism()
                    .map_or(1, |n| n.get().div_ceil(2))
                    .clamp(1, 4),
            )),
            metrics: Arc::new(Metrics::new()),
            token_uses: Arc::default(),
            graph: aobake_core::bake::GraphOptions::default(),
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

    /// Runs `work`, an import (its CPU time and memory grow with the
    /// upload), on a blocking thread, with at most as many at once as
    /// [`AppState::imports`] allows: a flood of uploads waits its turn
    /// rather than taking every core and all memory. The permit stays with
    /// the work, so a request that times out still holds it until its
    /// import ends.
    pub async fn import<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let permit = self.import_permit().await?;
        Self::import_holding(permit, work).await
    }

    /// A turn among the imports [`AppState::imports`] allows at once,
    /// waited for: a request that reads stored uploads to import them
    /// takes it first, so that requests waiting their turn hold none of
    /// those bytes.
    pub async fn import_permit(&self) -> Result<tokio::sync::OwnedSemaphorePermit, ApiError> {
        self.imports
            .clone()
            .acquire_owned()
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))
    }

    /// Runs `work` as [`AppState::import`] does, in the turn `permit`.
    pub async fn import_holding<T: Send + 'static>(
        permit: tokio::sync::OwnedSemaphorePermit,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            work()
        })
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))
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
    /// job became ready, so no worker is woken): on every server that
    /// shares the store, or on this one.
    pub fn publish(&self, bake: &crate::store::BakeRow) {
        let event = BakeEvent::of(bake);
        let local = match &self.shared_events {
            Some(shared) => shared.send(event).err().map(|e| e.0),
            None => Some(event),
        };
        if let Some(event) = local {
            let _ = self.events.send(event);
        }
    }

    /// Hears bake events from the other servers on the store and sends
    /// this one's to them, where the store is shared (see
    /// [`crate::store::Store::share_events`]); else events stay here.
    pub async fn share_events(&mut self) -> crate::store::Result<()> {
        self.shared_events = self.store.share_events(self.events.clone()).await?;
        Ok(())
    }
}
