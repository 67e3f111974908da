//! `POST /v1/characters` and `POST /v1/clips`: untrusted glTF in, a digest
//! and the `inspect` summary out. A `.glb` (or self-contained `.gltf`)
//! comes as the body; a `.gltf` with side files as `multipart/form-data`
//! (the first part is the main file, the others are named by their file
//! names, which are the only places its URIs may point to). The same bytes
//! give the same digest, so uploading twice is harmless.

// BUNDLE: the content type of a `.gltf` and its side files as one body
// (the framing of `UploadBytes::to_blob`, whose sha256 is the upload
// digest), as the one client sends it.
use aobake_api::schema::{Digest, Refusals};
use aobake_api::{Uploaded, client::BUNDLE};
use aobake_core::{
    SideFile,
    bake::{MAX_SIDE_FILES, UploadBytes},
    import_character, import_clips,
    summary::Summary,
};
use axum::{
    Json, Router,
    body::Bytes,
    extract::{FromRequest, Multipart, Request, State},
    http::{HeaderName, StatusCode, header},
    routing::{get, post},
};
use serde::Deserialize;

use crate::{
    auth::{Need, Read, Submit},
    error::{ApiError, ApiResult, Problem},
    extract::{ApiPath, ApiQuery},
    state::AppState,
    store::UploadRow,
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/characters", post(post_character))
        .route("/v1/characters/{digest}", get(get_upload))
        .route("/v1/clips", post(post_clips))
        .route("/v1/clips/{digest}", get(get_clips))
}

/// Reads the body: one file, a bundle, or multipart parts.
/// An upload's bytes and, for multipart, the main part's file name.
async fn read_upload(state: &AppState, req: Request) -> ApiResult<(UploadBytes, Option<String>)> {
    let content_type = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    let multipart = content_type.starts_with("multipart/form-data");
    let bundle = content_type.starts_with(BUNDLE);
    // Over the body limit (413), or cut off (400), as the rejection says.
    let unread = |code: &'static str, status: StatusCode, text: String| {
        if status == StatusCode::PAYLOAD_TOO_LARGE {
            ApiError::TooLarge(state.limits.max_body_bytes)
        } else {
            ApiError::bad(code, format!("cannot read the body: {text}"))
        }
    };
    if !multipart {
        let bytes = Bytes::from_request(req, &())
            .await
            .map_err(|e| unread("bad_body", e.status(), e.body_text()))?;
        if bytes.is_empty() {
            return Err(ApiError::bad(
                "empty_body",
                "the body is empty: send a .glb or .gltf",
            ));
        }
        if bundle {
            return UploadBytes::from_blob(&bytes, true)
                .map(|u| (u, None))
                .map_err(|e| ApiError::bad("bad_bundle", e.to_string()));
        }
        return Ok((UploadBytes::single(Vec::from(bytes)), None));
    }
    let mut parts = Multipart::from_request(req, &())
        .await
        .map_err(|e| ApiError::bad("bad_multipart", e.body_text()))?;
    let mut main: Option<Vec<u8>> = None;
    let mut main_name = None;
    let mut side_files = Vec::new();
    // A part's error says which: over the body limit (413), or what is
    // malformed (cut off, no boundary: 400).
    let part_error = |e: axum::extract::multipart::MultipartError| {
        unread("bad_multipart", e.status(), e.body_text())
    };
    while let Some(field) = parts.next_field().await.map_err(part_error)? {
        let name = field
            .file_name()
            .or(field.name())
            .unwrap_or_default()
            .to_owned();
        let bytes = field.bytes().await.map_err(part_error)?.into();
        if main.is_none() {
            main = Some(bytes);
            main_name = Some(name);
        } else {
            if name.is_empty() {
                return Err(ApiError::bad(
                    "bad_multipart",
                    "every side file needs a file name (the name its URI uses)",
                ));
            }
            if side_files.len() == MAX_SIDE_FILES {
                return Err(ApiError::bad(
                    "bad_multipart",
                    format!(
                        "more than {MAX_SIDE_FILES} side files: send the files the glTF refers to"
                    ),
                ));
            }
            side_files.push(SideFile { name, bytes });
        }
    }
    let main =
        main.ok_or_else(|| ApiError::bad("empty_body", "the multipart body has no parts"))?;
    Ok((UploadBytes { main, side_files }, main_name))
}

/// What the uploader calls the file, kept to show people (the dashboard
/// lists characters by it): its last path component, without control
/// characters, at most 200 characters.
fn file_name(given: Option<String>) -> Option<String> {
    let given = given?;
    shown(given.rsplit(['/', '\\']).next().unwrap_or_default())
}

/// A name as people will see it: without control characters or the
/// bidirectional overrides that make text read otherwise than it is, at
/// most 200 characters.
fn shown(name: &str) -> Option<String> {
    let bidi = |c: char| matches!(c, '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}');
    let clean: String = name
        .chars()
        .filter(|&c| !c.is_control() && !bidi(c))
        .take(200)
        .collect();
    let clean = clean.trim();
    (!clean.is_empty()).then(|| clean.to_owned())
}

/// The optional name of an upload sent as a raw body (multipart uploads
/// name it with the main part's file name).
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct NameQuery {
    /// The uploaded file's name, as the uploader knows it (`Fox.glb`).
    name: Option<String>,
}

async fn store_upload(
    state: &AppState,
    upload: &UploadBytes,
    kind: &str,
    summary: serde_json::Value,
) -> ApiResult<(StatusCode, Json<Uploaded>)> {
    let blob = upload.to_blob();
    let digest = upload.digest();
    // The row first: it marks the blob as a source, which `read` tokens
    // may not download (routes/assets.rs), before the blob exists. A blob
    // that then fails to store is stored by the next upload of it.
    let created = state
        .store
        .put_upload(&UploadRow {
            digest: digest.clone(),
            kind: kind.to_owned(),
            bundle: upload.is_bundle(),
            bytes: blob.len() as i64,
            summary: summary.clone(),
        })
        .await?;
    state.blobs.put(&digest, &blob).await?;
    if created {
        return Ok((StatusCode::CREATED, Json(Uploaded { digest, summary })));
    }
    // Uploaded before: the stored summary (with the first upload's name)
    // is the one every page shows.
    let stored = state
        .store
        .upload(&digest, kind)
        .await?
        .map_or(summary, |row| row.summary);
    Ok((
        StatusCode::OK,
        Json(Uploaded {
            digest,
            summary: stored,
        }),
    ))
}

#[utoipa::path(post, path = "/v1/characters", tag = "uploads", params(NameQuery),
    request_body(description = "A .glb or self-contained .gltf as the body, a bundle of a .gltf and its side files, or multipart/form-data whose first part is the .gltf and whose other parts are its side files: each part's file name (its Content-Disposition filename, else its field name) is the name the glTF's URI resolves to; parts it does not refer to are left out, with a warning",
        content((FileBytes = "model/gltf-binary"), (FileBytes = "model/gltf+json"), (FileBytes = "application/vnd.aobake.bundle"), (MultipartUpload = "multipart/form-data"))),
    security(("bearer" = ["submit"])),
    responses((status = 201, description = "Stored", body = Uploaded, headers(("Location" = String, description = "The upload's record (GET)"))), (status = 200, description = "Already stored", body = Uploaded, headers(("Location" = String, description = "The upload's record (GET)"))), (status = 413, description = "Body over the limit", body = Problem, content_type = "application/problem+json"), (status = 422, description = "The upload cannot be imported", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn post_character(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiQuery(q): ApiQuery<NameQuery>,
    req: Request,
) -> ApiResult<(StatusCode, [(HeaderName, String); 1], Json<Uploaded>)> {
    let (upload, part_name) = read_upload(&state, req).await?;
    let name = file_name(q.name.or(part_name));
    let limits = state.import_limits.clone();
    let (summary, upload, left_out) = state
        .import(move || {
            let mut upload = upload;
            let left_out = upload.keep_referenced(&limits);
            let imported = import_character(upload.upload(), &limits)
                .map_err(|e| naming_left_out(e, &left_out))?;
            let mut s = serde_json::to_value(Summary::of(&imported.character, &imported.clips))
                .expect("summaries serialise");
            s["warnings"] = serde_json::json!(imported.warnings);
            s["name"] = serde_json::json!(name);
            s["scene"] = serde_json::json!(imported.name.as_deref().and_then(shown));
            Ok::<_, aobake_core::ImportError>((s, upload, left_out))
        })
        .await?
        .map_err(|e| ApiError::unimportable("the character cannot be imported", &e))?;
    let reply = store_upload(&state, &upload, "character", summary).await?;
    Ok(telling(reply, "characters", &left_out))
}

/// `e`, and when it names a side file the upload lacks, the parts sent
/// with it under names the glTF does not use (left out before the
/// import): a name that differs in case or folder is then in sight.
fn naming_left_out(
    mut e: aobake_core::ImportError,
    left_out: &[String],
) -> aobake_core::ImportError {
    if let aobake_core::ImportError::MissingFile { available, .. } = &mut e
        && !left_out.is_empty()
    {
        let sent: Vec<String> = left_out.iter().map(|n| format!("{n:?}")).collect();
        available.push_str(&format!(
            "; sent too, under names the glTF does not use: {}",
            sent.join(", ")
        ));
    }
    e
}

/// The reply to an upload: `Location` is its record under
/// `/v1/{collection}/`, and its warnings tell which files sent with it were
/// left out (the glTF does not refer to them). Said to this upload only:
/// the stored summary describes the character, not how it came.
fn telling(
    (status, Json(mut uploaded)): (StatusCode, Json<Uploaded>),
    collection: &str,
    left_out: &[String],
) -> (StatusCode, [(HeaderName, String); 1], Json<Uploaded>) {
    if !left_out.is_empty() {
        let notes = left_out.iter().map(|name| {
            serde_json::json!(format!(
                "{name:?} is not a file the glTF refers to: left out (the upload's digest covers only the files it uses)"
            ))
        });
        match uploaded.summary["warnings"].as_array_mut() {
            Some(w) => w.extend(notes),
            None => uploaded.summary["warnings"] = notes.collect(),
        }
    }
    let location = format!("/v1/{collection}/{}", uploaded.digest);
    (status, [(header::LOCATION, location)], Json(uploaded))
}

/// A file's bytes as a request or response body (OpenAPI's binary
/// string, which generated clients read as bytes, not as an array of
/// integers).
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)] // documents the body; it is read and sent as raw bytes
pub(crate) struct FileBytes(Vec<u8>);

/// A `.gltf` and its side files as `multipart/form-data`.
#[derive(utoipa::ToSchema)]
#[allow(dead_code)] // documents the form; the parts are read one by one
pub(crate) struct MultipartUpload {
    /// The `.gltf` first, then each side file as a part named by the file
    /// name its URIs use.
    files: Vec<FileBytes>,
}

#[derive(Debug, Deserialize, utoipa::ToSchema)]
pub(crate) struct ClipsQuery {
    /// The character whose skeleton the clips must drive.
    character: String,
    /// The uploaded file's name, as the uploader knows it.
    name: Option<String>,
}

#[utoipa::path(post, path = "/v1/clips", tag = "uploads", params(("character" = String, Query, description = "The character whose skeleton the clips drive"), ("name" = Option<String>, Query, description = "The uploaded file's name")),
    request_body(description = "A glTF file of animations, sent as for POST /v1/characters",
        content((FileBytes = "model/gltf-binary"), (FileBytes = "model/gltf+json"), (FileBytes = "application/vnd.aobake.bundle"), (MultipartUpload = "multipart/form-data"))),
    security(("bearer" = ["submit"])),
    responses((status = 201, description = "Stored", body = Uploaded, headers(("Location" = String, description = "The upload's record (GET)"))), (status = 200, description = "Already stored", body = Uploaded, headers(("Location" = String, description = "The upload's record (GET)"))), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), (status = 413, description = "Body over the limit", body = Problem, content_type = "application/problem+json"), (status = 422, description = "The upload cannot be imported", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn post_clips(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiQuery(q): ApiQuery<ClipsQuery>,
    req: Request,
) -> ApiResult<(StatusCode, [(HeaderName, String); 1], Json<Uploaded>)> {
    let character = upload_row(&state, &q.character, "character").await?;
    let (upload, part_name) = read_upload(&state, req).await?;
    let name = file_name(q.name.or(part_name));
    let limits = state.import_limits.clone();
    // The stored character is read in the import's turn (bakes::submit).
    let permit = state.import_permit().await?;
    let character = upload_bytes(&state, &character).await?;
    let (summary, upload, left_out) = AppState::import_holding(permit, move || {
        let mut upload = upload;
        let left_out = upload.keep_referenced(&limits);
        // Imported when it was uploaded: failing now is the server's
        // fault (a changed importer), not the clips'.
        let c = import_character(character.upload(), &limits).map_err(|e| {
            ApiError::Internal(format!("the stored character no longer imports: {e}"))
        })?;
        // No clip that drives the character is the importer's
        // `no_animations`.
        let (clips, warnings) = import_clips(upload.upload(), &c.character, &limits)
            .map_err(|e| {
                ApiError::unimportable(
                    "the clips cannot be imported",
                    &naming_left_out(e, &left_out),
                )
            })?;
        let names: Vec<serde_json::Value> = clips
            .iter()
            .map(|c| serde_json::json!({"name": c.name, "duration": c.duration}))
            .collect();
        Ok::<_, ApiError>((
            serde_json::json!({"clips": names, "warnings": warnings, "character": c.character.vertex_count(), "name": name}),
            upload,
            left_out,
        ))
    })
    .await??;
    let reply = store_upload(&state, &upload, "clips", summary).await?;
    Ok(telling(reply, "clips", &left_out))
}

/// An upload's bytes, checked to be of `kind`.
pub(crate) async fn load_upload(
    state: &AppState,
    digest: &str,
    kind: &str,
) -> ApiResult<UploadBytes> {
    let row = upload_row(state, digest, kind).await?;
    upload_bytes(state, &row).await
}

/// The record of the stored upload `digest` of `kind`; 404 without one.
pub(crate) async fn upload_row(state: &AppState, digest: &str, kind: &str) -> ApiResult<UploadRow> {
    crate::blobs::check_digest(digest)?;
    state
        .store
        .upload(digest, kind)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no {kind} upload {digest}")))
}

/// The files of the stored upload `row`.
pub(crate) async fn upload_bytes(state: &AppState, row: &UploadRow) -> ApiResult<UploadBytes> {
    let blob = state
        .read_blob(&row.digest, None)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("upload {} has no blob", row.digest)))?;
    UploadBytes::from_blob(&blob, row.bundle).map_err(|e| ApiError::Internal(e.to_string()))
}

#[utoipa::path(get, path = "/v1/characters/{digest}", tag = "uploads", params(("digest" = Digest, Path, description = "sha256 of the upload")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The upload", body = UploadRow), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn get_upload(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
) -> ApiResult<Json<UploadRow>> {
    find_upload(&state, &digest, "character").await
}

async fn find_upload(state: &AppState, digest: &str, kind: &str) -> ApiResult<Json<UploadRow>> {
    crate::blobs::check_digest(digest)?;
    Ok(Json(state.store.upload(digest, kind).await?.ok_or_else(
        || ApiError::NotFound(format!("no {kind} upload {digest}")),
    )?))
}

#[utoipa::path(get, path = "/v1/clips/{digest}", tag = "uploads", params(("digest" = Digest, Path, description = "sha256 of the upload")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The upload", body = UploadRow), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn get_clips(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
) -> ApiResult<Json<UploadRow>> {
    find_upload(&state, &digest, "clips").await
}
