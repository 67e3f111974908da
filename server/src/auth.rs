//! Bearer tokens with scopes (DESIGN §9): `read` (everything a dashboard
//! or CI shows: bakes, published assets, reports, previews, workers, but
//! not the uploaded sources), `submit` (all of `read`, and uploads, their
//! bytes, and bakes and their control), `worker` (the job protocol and
//! blobs) and `admin` (all of them, and tokens).
//! Only a token's sha256 is stored; a token is 32 random bytes in hex.

use axum::{extract::FromRequestParts, http::request::Parts};
use rand::RngExt as _;

use crate::{error::ApiError, state::AppState};

pub use aobake_api::Scope;

/// A new random token (64 hex digits).
pub fn new_token() -> String {
    let bytes: [u8; 32] = rand::rng().random();
    aobake_core::digest::hex(&bytes)
}

/// What is stored of a token.
pub fn token_hash(token: &str) -> String {
    aobake_core::digest::sha256_hex(token.as_bytes())
}

/// The caller, as its bearer token says.
#[derive(Debug, Clone)]
pub struct Caller {
    /// The token's name.
    pub name: String,
    /// Its scopes.
    pub scopes: Vec<Scope>,
    /// Its hash (the rate limiter's key).
    pub hash: String,
}

impl Caller {
    /// Whether the caller has `scope`, or one that includes it
    /// ([`Scope::includes`]: `admin` all, `submit` `read`).
    pub fn has(&self, scope: Scope) -> bool {
        self.scopes.iter().any(|s| s.includes(scope))
    }

    /// Refuses with 403 unless the caller has `scope` ([`Caller::has`]).
    pub fn require(&self, scope: Scope) -> Result<(), ApiError> {
        if self.has(scope) {
            Ok(())
        } else {
            Err(ApiError::Forbidden(scope.name()))
        }
    }
}

impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let header = parts
            .headers
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .ok_or(ApiError::Unauthorized)?;
        // The scheme is case-insensitive (RFC 9110 §11.1).
        let token = header
            .split_once(' ')
            .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
            .ok_or(ApiError::Unauthorized)?
            .1
            .trim();
        let hash = token_hash(token);
        let row = state
            .store
            .token(&hash)
            .await?
            .ok_or(ApiError::Unauthorized)?;
        let now = now_ms();
        if let Some(at) = row.expired(now) {
            return Err(ApiError::TokenExpired(at));
        }
        // When it was last used, to the minute: at most one write a
        // minute per token and server (this server's own record decides,
        // whatever the row says), off the request's path; a failed one
        // costs nothing.
        let due = {
            let mut uses = state
                .token_uses
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            let last = uses.entry(hash.clone()).or_insert(i64::MIN);
            let due = now.saturating_sub(*last) >= LAST_USED_EVERY_MS;
            if due {
                *last = now;
            }
            due
        };
        if due {
            let (store, hash) = (state.store.clone(), hash.clone());
            tokio::spawn(async move {
                let _ = store.token_used(&hash, now).await;
            });
        }
        let caller = Self {
            name: row.name,
            scopes: row.scopes.iter().filter_map(|s| Scope::parse(s)).collect(),
            hash,
        };
        state.limiter.check(&caller.hash)?;
        Ok(caller)
    }
}

/// How stale a token's `last_used_at` may get before a request writes it
/// again.
const LAST_USED_EVERY_MS: i64 = 60_000;

/// Milliseconds since the epoch, by this server's clock.
pub(crate) fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}

/// How often an open event stream asks whether its token is still valid.
const STREAM_RECHECK: std::time::Duration = std::time::Duration::from_secs(5);

impl Caller {
    /// `events` for as long as this caller's token stays valid: the
    /// stream ends within [`STREAM_RECHECK`] of the token being revoked
    /// or expiring, so an open dashboard tab stops hearing what its
    /// token may no longer read (its reconnection then gets the 401 and
    /// its reason). An outage of the database ends nothing.
    pub fn while_valid<S, T>(
        &self,
        state: &AppState,
        events: S,
    ) -> impl tokio_stream::Stream<Item = T> + Send + use<S, T>
    where
        S: tokio_stream::Stream<Item = T> + Send + 'static,
        T: Send + 'static,
    {
        use tokio_stream::StreamExt as _;
        let (ended, watch) = tokio::sync::watch::channel(());
        let (store, hash) = (state.store.clone(), self.hash.clone());
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    // The stream was dropped: the client went.
                    () = ended.closed() => return,
                    () = tokio::time::sleep(STREAM_RECHECK) => {}
                }
                let valid = match store.token(&hash).await {
                    Ok(Some(row)) => row.expired(now_ms()).is_none(),
                    Ok(None) => false,
                    Err(_) => true,
                };
                if !valid {
                    let _ = ended.send(());
                    return;
                }
            }
        });
        let end = tokio_stream::wrappers::WatchStream::from_changes(watch).map(|()| None);
        events
            .map(Some)
            .merge(end)
            .take_while(Option::is_some)
            .filter_map(|e| e)
    }
}

/// A scope as a type, for [`Need`].
pub trait NeedScope: Send + Sync + 'static {
    /// The scope.
    const SCOPE: Scope;
}

macro_rules! scope_marker {
    ($name:ident, $scope:expr, $doc:literal) => {
        #[doc = $doc]
        #[derive(Debug)]
        pub struct $name;
        impl NeedScope for $name {
            const SCOPE: Scope = $scope;
        }
    };
}
scope_marker!(Read, Scope::Read, "Needs the `read` scope.");
scope_marker!(Submit, Scope::Submit, "Needs the `submit` scope.");
scope_marker!(Worker, Scope::Worker, "Needs the `worker` scope.");
scope_marker!(Admin, Scope::Admin, "Needs the `admin` scope.");

/// A caller with scope `S`, checked while extracting, before the body is
/// read: a token without the scope gets 403 whatever it sends.
#[derive(Debug)]
pub struct Need<S>(pub Caller, std::marker::PhantomData<S>);

impl<S: NeedScope> FromRequestParts<AppState> for Need<S> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let caller = Caller::from_request_parts(parts, state).await?;
        caller.require(S::SCOPE)?;
        Ok(Self(caller, std::marker::PhantomData))
    }
}
