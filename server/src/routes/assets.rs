//! `GET /v1/assets/{digest}`: published bytes (assets, reports, plots) by
//! content digest (an uploaded character or clip file too, for a token
//! that may upload: `read` reaches outputs, not the studio's sources), and `GET /v1/previews/{digest}`: a preview PNG, served
//! as an image. The digest is the strong `ETag`, so `If-None-Match`
//! answers 304, and a single `Range` answers 206 with those bytes.

use aobake_api::schema::{Digest, Refusals};
use axum::{
    Router,
    extract::State,
    http::{HeaderMap, HeaderValue, StatusCode, header},
    response::{IntoResponse, Response},
    routing::get,
};

use crate::{
    auth::{Caller, Need, Read, Scope},
    error::{ApiError, ApiResult, Problem},
    extract::ApiPath,
    state::AppState,
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/assets/{digest}", get(asset))
        .route("/v1/previews/{digest}", get(preview))
}

#[utoipa::path(get, path = "/v1/assets/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the bytes"), ("If-None-Match" = Option<String>, Header, description = "An ETag"), ("Range" = Option<String>, Header, description = "One byte range (several are served whole)"), ("If-Range" = Option<String>, Header, description = "The range only if this is still the ETag; otherwise the whole blob")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The bytes (an uploaded source needs `submit`: 403 for `read` alone)", content_type = "application/octet-stream", body = crate::routes::uploads::FileBytes), (status = 206, description = "The requested range", content_type = "application/octet-stream", body = crate::routes::uploads::FileBytes), (status = 304, description = "Not modified (If-None-Match)"), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), (status = 416, description = "A byte range the blob does not have, or a malformed one; `Content-Range: bytes */LEN` gives the length", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn asset(
    State(state): State<AppState>,
    caller: Caller,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    crate::blobs::check_digest(&digest)?;
    // Sources need submit, everything else read: a caller with both (an
    // admin, or a submit token, which includes read) is let through
    // without asking the store.
    if !(caller.has(Scope::Read) && caller.has(Scope::Submit)) {
        let mut source = false;
        for kind in ["character", "clips"] {
            source |= state.store.upload(&digest, kind).await?.is_some();
        }
        caller.require(if source { Scope::Submit } else { Scope::Read })?;
    }
    serve(&state, &digest, &headers, "application/octet-stream").await
}

#[utoipa::path(get, path = "/v1/previews/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the PNG, from GET /v1/bakes/{id}/previews"), ("If-None-Match" = Option<String>, Header, description = "An ETag")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The PNG (an APNG for an animation)", content_type = "image/png", body = crate::routes::uploads::FileBytes), (status = 304, description = "Not modified (If-None-Match)"), (status = 404, description = "No such preview", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn preview(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    crate::blobs::check_digest(&digest)?;
    // Only PNGs are served as images: another blob under this route would
    // be a lie about its type.
    let head = state.read_blob(&digest, Some((0, 8))).await?;
    if head.as_deref() != Some(b"\x89PNG\r\n\x1a\n".as_slice()) {
        return Err(ApiError::NotFound(format!("no preview {digest}")));
    }
    serve(&state, &digest, &headers, "image/png").await
}

/// A blob by digest with its content type, `ETag`, and ranges.
async fn serve(
    state: &AppState,
    digest: &str,
    headers: &HeaderMap,
    content_type: &'static str,
) -> ApiResult<Response> {
    let digest = digest.to_owned();
    crate::blobs::check_digest(&digest)?;
    let len = state
        .blobs
        .len(&digest)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no asset {digest}")))?;
    let etag = HeaderValue::from_str(&format!("\"{digest}\"")).expect("hex is a valid header");
    let matches = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.split(',')
                .any(|t| t.trim() == "*" || t.trim().trim_start_matches("W/") == etag)
        });
    let common = [
        (header::ETAG, etag.clone()),
        (header::ACCEPT_RANGES, HeaderValue::from_static("bytes")),
        (
            header::CACHE_CONTROL,
            HeaderValue::from_static("private, max-age=31536000, immutable"),
        ),
    ];
    if matches {
        return Ok((StatusCode::NOT_MODIFIED, common).into_response());
    }
    // RFC 9110: a range in another unit than bytes is ignored, and so is
    // any range when If-Range names another representation (an ETag other
    // than this one, or a date: these blobs have none).
    // (The unit is case-insensitive: `Bytes=` is read as `bytes=`.)
    let range = headers
        .get(header::RANGE)
        .and_then(|v| v.to_str().ok())
        .and_then(|r| {
            let r = r.trim_start();
            let (unit, set) = r.split_at_checked(6)?;
            unit.eq_ignore_ascii_case("bytes=")
                .then(|| (r, format!("bytes={set}")))
        })
        .filter(|_| {
            headers
                .get(header::IF_RANGE)
                .is_none_or(|v| v.as_bytes() == etag.as_bytes())
        });
    if let Some((range, bytes_range)) = range {
        // A malformed or unsatisfiable byte range is a 416, whose
        // Content-Range tells a resuming client the whole length.
        let ranges = http_range_header::parse_range_header(&bytes_range)
            .and_then(|r| r.validate(len))
            .map_err(|_| ApiError::RangeNotSatisfiable {
                range: range.to_owned(),
                len,
            })?;
        // One range is served as 206; several are served whole (RFC 9110
        // lets a server ignore a multi-range request).
        if let [r] = ranges.as_slice() {
            let (start, end) = (*r.start(), *r.end() + 1);
            let bytes = state
                .read_blob(&digest, Some((start, end)))
                .await?
                .ok_or_else(|| ApiError::NotFound(format!("no asset {digest}")))?;
            let content_range = format!("bytes {start}-{}/{len}", end - 1);
            return Ok((
                StatusCode::PARTIAL_CONTENT,
                common,
                [(header::CONTENT_RANGE, content_range)],
                bytes,
            )
                .into_response());
        }
    }
    let bytes = state
        .read_blob(&digest, None)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no asset {digest}")))?;
    Ok((
        StatusCode::OK,
        common,
        [(header::CONTENT_TYPE, content_type)],
        bytes,
    )
        .into_response())
}
