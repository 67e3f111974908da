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
        .route("/v1/assets/{digest}", get(asset).head(asset_head))
        .route("/v1/previews/{digest}", get(preview).head(preview_head))
}

#[utoipa::path(get, path = "/v1/assets/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the bytes"), ("If-None-Match" = Option<String>, Header, description = "An ETag"), ("Range" = Option<String>, Header, description = "One byte range (several are served whole)"), ("If-Range" = Option<String>, Header, description = "The range only if this is still the ETag; otherwise the whole blob")),
    security(("bearer" = ["read"])),
    responses(
        (status = 200, description = "The bytes (an uploaded source needs `submit`: 403 for `read` alone)", content_type = "application/octet-stream", body = crate::routes::uploads::FileBytes,
            headers(("ETag" = String, description = "The digest in quotes: a strong validator, for If-None-Match and If-Range"), ("Accept-Ranges" = String, description = "`bytes`"), ("Cache-Control" = String, description = "`private, max-age=31536000, immutable`: a digest's bytes never change"), ("Content-Length" = u64, description = "The bytes' length"))),
        (status = 206, description = "The requested range", content_type = "application/octet-stream", body = crate::routes::uploads::FileBytes,
            headers(("Content-Range" = String, description = "`bytes FIRST-LAST/LEN`"), ("ETag" = String, description = "The digest in quotes"), ("Content-Length" = u64, description = "The range's length"))),
        (status = 304, description = "Not modified (If-None-Match)", headers(("ETag" = String, description = "The digest in quotes"))),
        (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "A byte range the blob does not have, or a malformed one", body = Problem, content_type = "application/problem+json",
            headers(("Content-Range" = String, description = "`bytes */LEN`: the blob's length, which tells a resuming client it has it all"))),
        Refusals))]
pub(crate) async fn asset(
    State(state): State<AppState>,
    caller: Caller,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    an_asset(&state, &caller, &digest, &headers, Body::Bytes).await
}

#[utoipa::path(head, path = "/v1/assets/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the bytes"), ("If-None-Match" = Option<String>, Header, description = "An ETag"), ("Range" = Option<String>, Header, description = "One byte range"), ("If-Range" = Option<String>, Header, description = "The range only if this is still the ETag")),
    security(("bearer" = ["read"])),
    responses(
        (status = 200, description = "GET's headers without the bytes: whether a digest is there, and its length", headers(("ETag" = String, description = "The digest in quotes"), ("Accept-Ranges" = String, description = "`bytes`"), ("Cache-Control" = String, description = "As GET's"), ("Content-Length" = u64, description = "The bytes' length"))),
        (status = 206, description = "GET's headers for the range", headers(("Content-Range" = String, description = "`bytes FIRST-LAST/LEN`"), ("Content-Length" = u64, description = "The range's length"))),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "Not found (no body)"),
        (status = 416, description = "A byte range the blob does not have", headers(("Content-Range" = String, description = "`bytes */LEN`"))),
        Refusals))]
pub(crate) async fn asset_head(
    State(state): State<AppState>,
    caller: Caller,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    an_asset(&state, &caller, &digest, &headers, Body::None).await
}

/// An asset's answer to GET or HEAD, for a caller let through.
async fn an_asset(
    state: &AppState,
    caller: &Caller,
    digest: &str,
    headers: &HeaderMap,
    body: Body,
) -> ApiResult<Response> {
    let_through(state, caller, digest).await?;
    serve(state, digest, headers, "application/octet-stream", body).await
}

/// Sources need submit, everything else read: a caller with both (an
/// admin, or a submit token, which includes read) is let through without
/// asking the store.
async fn let_through(state: &AppState, caller: &Caller, digest: &str) -> ApiResult<()> {
    crate::blobs::check_digest(digest)?;
    if !(caller.has(Scope::Read) && caller.has(Scope::Submit)) {
        let mut source = false;
        for kind in ["character", "clips"] {
            source |= state.store.upload(digest, kind).await?.is_some();
        }
        caller.require(if source { Scope::Submit } else { Scope::Read })?;
    }
    Ok(())
}

#[utoipa::path(get, path = "/v1/previews/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the PNG, from GET /v1/bakes/{id}/previews"), ("If-None-Match" = Option<String>, Header, description = "An ETag")),
    security(("bearer" = ["read"])),
    responses(
        (status = 200, description = "The PNG (an APNG for an animation)", content_type = "image/png", body = crate::routes::uploads::FileBytes,
            headers(("ETag" = String, description = "The digest in quotes"), ("Cache-Control" = String, description = "`private, max-age=31536000, immutable`"), ("Content-Length" = u64, description = "The PNG's length"))),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such preview", body = Problem, content_type = "application/problem+json"),
        Refusals))]
pub(crate) async fn preview(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    a_png(&state, &digest).await?;
    serve(&state, &digest, &headers, "image/png", Body::Bytes).await
}

#[utoipa::path(head, path = "/v1/previews/{digest}", tag = "assets", params(("digest" = Digest, Path, description = "sha256 of the PNG"), ("If-None-Match" = Option<String>, Header, description = "An ETag")),
    security(("bearer" = ["read"])),
    responses(
        (status = 200, description = "GET's headers without the PNG", headers(("ETag" = String, description = "The digest in quotes"), ("Content-Length" = u64, description = "The PNG's length"))),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such preview (no body)"),
        Refusals))]
pub(crate) async fn preview_head(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    a_png(&state, &digest).await?;
    serve(&state, &digest, &headers, "image/png", Body::None).await
}

/// Only PNGs are served as images: another blob under the previews'
/// route would be a lie about its type.
async fn a_png(state: &AppState, digest: &str) -> ApiResult<()> {
    crate::blobs::check_digest(digest)?;
    let head = state.read_blob(digest, Some((0, 8))).await?;
    if head.as_deref() != Some(b"\x89PNG\r\n\x1a\n".as_slice()) {
        return Err(ApiError::NotFound(format!("no preview {digest}")));
    }
    Ok(())
}

/// Whether a response carries the bytes (GET) or only their headers
/// (HEAD, which reads none).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Body {
    Bytes,
    None,
}

/// A blob by digest with its content type, `ETag`, and ranges; with
/// [`Body::None`] (HEAD) the same status and headers, no byte read.
async fn serve(
    state: &AppState,
    digest: &str,
    headers: &HeaderMap,
    content_type: &'static str,
    body: Body,
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
    let mut span = None;
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
            span = Some((*r.start(), *r.end() + 1));
        }
    }
    let (status, length) = match span {
        Some((start, end)) => (StatusCode::PARTIAL_CONTENT, end - start),
        None => (StatusCode::OK, len),
    };
    let mut res = match body {
        Body::Bytes => state
            .read_blob(&digest, span)
            .await?
            .ok_or_else(|| ApiError::NotFound(format!("no asset {digest}")))?
            .into_response(),
        // HEAD: the length GET would send, and no body.
        Body::None => [(header::CONTENT_LENGTH, HeaderValue::from(length))].into_response(),
    };
    *res.status_mut() = status;
    let h = res.headers_mut();
    h.extend(common);
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    if let Some((start, end)) = span {
        let content_range = format!("bytes {start}-{}/{len}", end - 1);
        h.insert(
            header::CONTENT_RANGE,
            HeaderValue::from_str(&content_range).expect("digits"),
        );
    }
    Ok(res)
}
