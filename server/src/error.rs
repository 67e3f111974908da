//! One error type for the API and its one mapping to the wire: RFC 9457
//! problem+json with `type`, `title`, `status`, `detail` and `code`.
//! Internal errors get a generic detail naming the request's id; what
//! went wrong is logged once, with that id, by `app::log_failures` (an
//! item of a batch answer, which is not a response of its own, by
//! [`ApiError::log_internal`] in its route).

use axum::{
    http::{HeaderValue, StatusCode, header},
    response::{IntoResponse, Response},
};

use crate::{blobs::BlobError, store::StoreError};

/// Why a request failed.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ApiError {
    /// The request is malformed or names something invalid.
    #[error("{detail}")]
    BadRequest {
        /// Machine-readable code.
        code: &'static str,
        /// What is wrong.
        detail: String,
    },
    /// An upload is not a character aobake can bake, or a request cannot
    /// be served for what is in one.
    #[error("{detail}")]
    Unprocessable {
        /// The importer's reason ([`aobake_core::ImportError::code`]),
        /// when an import failed.
        reason: Option<&'static str>,
        /// Where in the glTF JSON, as a JSON Pointer.
        pointer: Option<String>,
        /// What is wrong.
        detail: String,
    },
    /// No or unknown bearer token.
    #[error("a valid bearer token is required")]
    Unauthorized,
    /// The token's time ran out (ms since the epoch when it did).
    #[error("this token expired at {}; make another (aobake token create --expires-in …)", humantime::format_rfc3339_seconds(std::time::UNIX_EPOCH + std::time::Duration::from_millis(u64::try_from(*.0).unwrap_or(0))))]
    TokenExpired(i64),
    /// The token lacks the scope.
    #[error("this token lacks the {0:?} scope")]
    Forbidden(&'static str),
    /// Nothing by that name.
    #[error("{0}")]
    NotFound(String),
    /// The route exists but not under this method.
    #[error("{0}")]
    MethodNotAllowed(String),
    /// The state forbids it, or the lease is gone.
    #[error("{0}")]
    Conflict(String),
    /// The body is over the limit.
    #[error("the body is over the limit of {0} bytes")]
    TooLarge(u64),
    /// A byte range the blob does not have (or a malformed one): 416
    /// with `Content-Range: bytes */LEN`, which tells a resuming client
    /// (`curl -C -`, `wget -c`) the file is complete.
    #[error("cannot serve {range:?} of {len} bytes")]
    RangeNotSatisfiable {
        /// The `Range` header as sent.
        range: String,
        /// The blob's length.
        len: u64,
    },
    /// Too many requests for this token.
    #[error("too many requests; retry after {0} s")]
    RateLimited(u64),
    /// The database or the blob store does not answer (restarting,
    /// unreachable): the request can be sent again after this many
    /// seconds.
    #[error("{0} is not answering; retry after {1} s")]
    Unavailable(Outage, u64),
    /// A bug or an outage; the detail is logged, not sent.
    #[error("internal error: {0}")]
    Internal(String),
}

/// What a 503 says does not answer, so that an operator looks in the
/// right place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outage {
    /// SQLite or PostgreSQL.
    Database,
    /// The blob store (local disk, or an S3-compatible bucket).
    Blobs,
    /// The blob store's bucket, which is not there.
    Bucket,
}

impl Outage {
    /// What a blob store that does not serve names: its bucket, when that
    /// is what is missing, else the store.
    pub(crate) fn of_blobs(e: &BlobError) -> Self {
        match e {
            BlobError::NoBucket(_) => Self::Bucket,
            _ => Self::Blobs,
        }
    }
}

impl std::fmt::Display for Outage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Database => "the database",
            Self::Blobs => "the blob store",
            Self::Bucket => {
                "the blob store (its bucket does not exist: create it again or restore it, and the service goes on)"
            }
        })
    }
}

impl ApiError {
    /// A 400 with a code.
    pub fn bad(code: &'static str, detail: impl Into<String>) -> Self {
        Self::BadRequest {
            code,
            detail: detail.into(),
        }
    }

    /// A 422 for an upload that `import` refused: `what` says which file
    /// ("the character cannot be imported").
    pub fn unimportable(what: &str, import: &aobake_core::ImportError) -> Self {
        Self::Unprocessable {
            reason: Some(import.code()),
            pointer: import.pointer(),
            detail: format!("{what}: {import}"),
        }
    }

    /// A 422 that is not the importer's.
    pub fn unprocessable(detail: impl Into<String>) -> Self {
        Self::Unprocessable {
            reason: None,
            pointer: None,
            detail: detail.into(),
        }
    }

    fn parts(&self) -> (StatusCode, &'static str, &'static str) {
        match self {
            Self::BadRequest { code, .. } => (StatusCode::BAD_REQUEST, code, "Bad request"),
            Self::Unprocessable { .. } => (
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_upload",
                "The upload cannot be used",
            ),
            Self::Unauthorized => (StatusCode::UNAUTHORIZED, "unauthorized", "Unauthorized"),
            Self::TokenExpired(_) => (StatusCode::UNAUTHORIZED, "token_expired", "Unauthorized"),
            Self::Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden", "Forbidden"),
            Self::NotFound(_) => (StatusCode::NOT_FOUND, "not_found", "Not found"),
            Self::MethodNotAllowed(_) => (
                StatusCode::METHOD_NOT_ALLOWED,
                "method_not_allowed",
                "Method not allowed",
            ),
            Self::Conflict(_) => (StatusCode::CONFLICT, "conflict", "Conflict"),
            Self::TooLarge(_) => (
                StatusCode::PAYLOAD_TOO_LARGE,
                "too_large",
                "Payload too large",
            ),
            Self::RangeNotSatisfiable { .. } => (
                StatusCode::RANGE_NOT_SATISFIABLE,
                "bad_range",
                "Range not satisfiable",
            ),
            Self::RateLimited(_) => (
                StatusCode::TOO_MANY_REQUESTS,
                "rate_limited",
                "Too many requests",
            ),
            Self::Unavailable(..) => (
                StatusCode::SERVICE_UNAVAILABLE,
                "unavailable",
                "Service unavailable",
            ),
            Self::Internal(_) => (
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal",
                "Internal server error",
            ),
        }
    }
}

pub use aobake_api::Problem;

impl ApiError {
    /// The problem+json body that tells a client of this error (an
    /// internal error only generically: what went wrong is logged with the
    /// request's id, by `app::log_failures` or [`ApiError::log_internal`],
    /// never sent).
    pub fn problem(&self) -> Problem {
        if let Self::Internal(_) = self {
            return Self::internal_problem("?");
        }
        let (status, code, title) = self.parts();
        let mut problem = Self::problem_saying(status, code, title, self.to_string());
        if let Self::Unprocessable {
            reason, pointer, ..
        } = self
        {
            problem.reason = reason.map(str::to_owned);
            problem.pointer.clone_from(pointer);
        }
        problem
    }

    /// Logs internal error `what` under its request's id (`request`, the
    /// `x-request-id` header; `?` without) and `place` (the route, and
    /// more), and gives the problem that names the id.
    pub fn log_internal(
        request: Option<&HeaderValue>,
        place: impl std::fmt::Display,
        what: &str,
    ) -> Problem {
        let id = request.and_then(|v| v.to_str().ok()).unwrap_or("?");
        log_line!("error: internal, request {id} ({place}): {what}");
        Self::internal_problem(id)
    }

    /// The problem of an internal error whose log line names `request`
    /// (the response's `x-request-id`), as its detail says.
    pub fn internal_problem(request: &str) -> Problem {
        let (status, code, title) = Self::Internal(String::new()).parts();
        Self::problem_saying(
            status,
            code,
            title,
            format!("the server failed; its log has the error under request id {request}"),
        )
    }

    fn problem_saying(status: StatusCode, code: &str, title: &str, detail: String) -> Problem {
        Problem {
            kind: format!("https://aobake.dev/problems/{code}"),
            title: title.to_owned(),
            status: status.as_u16(),
            detail,
            code: code.to_owned(),
            reason: None,
            pointer: None,
        }
    }
}

/// What an internal error's response carries to the layer that logs it
/// with the request's id (`app::log_failures`).
#[derive(Debug, Clone)]
pub struct InternalFailure(pub String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, _, _) = self.parts();
        let mut res = (status, axum::Json(self.problem())).into_response();
        res.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        // An internal error is logged by `app::log_failures`, with the
        // request's id, which its answer then names.
        if let Self::Internal(d) = self {
            res.extensions_mut().insert(InternalFailure(d));
            return res;
        }
        if let Self::RateLimited(s) | Self::Unavailable(_, s) = self {
            res.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if let Self::RangeNotSatisfiable { len, .. } = self {
            res.headers_mut().insert(
                header::CONTENT_RANGE,
                HeaderValue::from_str(&format!("bytes */{len}")).expect("digits"),
            );
        }
        if matches!(self, Self::Unauthorized | Self::TokenExpired(_)) {
            res.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"aobake\""),
            );
        }
        res
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::LeaseLost(m) | StoreError::Conflict(m) => Self::Conflict(m),
            e @ StoreError::Revoked(_) => Self::Conflict(e.to_string()),
            StoreError::NotFound(m) => Self::NotFound(m),
            StoreError::Database(e) if crate::store::unreachable(&e) => {
                log_line!("error: the database is not answering: {e}");
                Self::Unavailable(Outage::Database, DATABASE_RETRY_SECS)
            }
            other => Self::Internal(other.to_string()),
        }
    }
}

/// What a client is told to wait while the database does not answer.
const DATABASE_RETRY_SECS: u64 = 2;

/// What a client is told to wait while the blob store does not answer.
pub(crate) const BLOBS_RETRY_SECS: u64 = 5;

impl From<BlobError> for ApiError {
    fn from(e: BlobError) -> Self {
        match e {
            BlobError::DigestMismatch { .. } | BlobError::BadDigest(_) => {
                Self::bad("bad_digest", e.to_string())
            }
            _ if e.outage() => {
                log_line!("error: not answering (503): {e}");
                Self::Unavailable(Outage::of_blobs(&e), BLOBS_RETRY_SECS)
            }
            // (A bucket that is not there is an outage, above.)
            BlobError::Io(_)
            | BlobError::Store(_)
            | BlobError::Config(_)
            | BlobError::NoBucket(_) => Self::Internal(e.to_string()),
        }
    }
}

/// Handler results.
pub type ApiResult<T> = Result<T, ApiError>;
