//! Bakes: submit (planned into jobs here, the one place the server meets
//! core's job graph), list, inspect with every job, the report, live
//! events, control, and the cache by bake key that CI reads.

use aobake_api::schema::{Digest, Refusals};
use aobake_api::{BakeKey, BakeRequest, BakeView, PatchBody, PreviewItem, PreviewList, Progress};
use std::collections::HashMap;
use std::convert::Infallible;
use std::time::Duration;

use aobake_core::{
    bake::{Bake, BakeInputs, BakeParams, ClipListError, bake_key, check_clip_list},
    method::Method,
};
use axum::{
    Json, Router,
    extract::State,
    http::{StatusCode, header},
    response::{
        IntoResponse, Response,
        sse::{Event, KeepAlive, Sse},
    },
    routing::{get, post},
};
use serde::Deserialize;
use tokio_stream::{Stream, StreamExt as _, wrappers::BroadcastStream};

use super::uploads::{upload_bytes, upload_row};
use crate::{
    auth::{Need, Read, Submit},
    error::{ApiError, ApiResult, Problem},
    extract::{ApiPath, ApiQuery, Body},
    state::AppState,
    store::{Action, BakeRow, JobRow, NewBake, NewJob},
};

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/bakes", post(submit).get(list))
        .route("/v1/bakes/{id}", get(show).patch(patch))
        .route("/v1/bakes/{id}/report", get(report))
        .route("/v1/bakes/{id}/previews", get(previews))
        .route("/v1/bakes/{id}/events", get(events))
        .route("/v1/events", get(all_events))
        .route("/v1/bakes/{id}/{action}", post(control))
        .route("/v1/cache/{key}", get(cache))
        .route("/v1/keys", post(key))
        .route("/v1/characters/{digest}/bakes", get(versions))
}

fn view(bake: BakeRow, jobs: Option<Vec<JobRow>>) -> BakeView {
    // With its jobs, from them: the bake's row and its jobs are read one
    // after the other, and a heartbeat between the two would show a job
    // further on than the bar.
    let (done, redo) = match &jobs {
        Some(jobs) => {
            let (done, redo) = jobs.iter().fold((0, 0), |(done, redo), j| match j.state {
                crate::store::JobState::Completed => (done + j.work, redo),
                crate::store::JobState::Running => {
                    (done + j.reached, redo + (j.reached - j.progress).max(0))
                }
                _ => (done + j.reached, redo),
            });
            (done.min(bake.total_work), redo)
        }
        None => (crate::state::progress_done(&bake), bake.redo_work),
    };
    BakeView {
        progress: Progress {
            done,
            total: bake.total_work,
            redo,
        },
        bake,
        jobs,
        rebakes: None,
    }
}

#[utoipa::path(post, path = "/v1/bakes", tag = "bakes", request_body = BakeRequest,
    security(("bearer" = ["submit"])),
    responses((status = 202, description = "Accepted (or already running)", body = BakeView, headers(("Location" = String, description = "The bake (`/v1/bakes/{id}`)"))), (status = 200, description = "Already baked: the finished bake", body = BakeView, headers(("Location" = String, description = "The bake (`/v1/bakes/{id}`)"))), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), (status = 422, description = "The upload cannot be imported", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn submit(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    Body(req): Body<BakeRequest>,
) -> ApiResult<Response> {
    let method: Method = req
        .method
        .parse()
        .map_err(|e: String| ApiError::bad("bad_method", e))?;
    let params = BakeParams::with_overrides(method, &req.params)
        .map_err(|e| ApiError::bad("bad_params", e.to_string()))?;
    match check_clip_list(&req.clips) {
        Ok(()) => {}
        Err(e @ ClipListError::TooMany(_)) => {
            return Err(ApiError::bad("too_many_clips", e.to_string()));
        }
        Err(ClipListError::Twice(_, again)) => {
            return Err(ApiError::bad(
                "duplicate_clips",
                format!("clip file {} is named twice", req.clips[again]),
            ));
        }
    }
    // The records first: what the bake would hold in memory is known
    // before a byte of it is read, and read only in the import's turn.
    let character = upload_row(&state, &req.character, "character").await?;
    let mut clip_rows = Vec::new();
    for c in &req.clips {
        clip_rows.push(upload_row(&state, c, "clips").await?);
    }
    let bytes = std::iter::once(&character)
        .chain(&clip_rows)
        .map(|row| u64::try_from(row.bytes).unwrap_or(0))
        .fold(0u64, u64::saturating_add);
    let max_bytes = state.limits.max_bake_input_bytes;
    if bytes > max_bytes {
        return Err(ApiError::bad(
            "too_much_input",
            format!(
                "the character and clip files are {bytes} bytes together, over the limit of {max_bytes}: bake fewer or smaller clip files"
            ),
        ));
    }
    let permit = state.import_permit().await?;
    let character = upload_bytes(&state, &character).await?;
    let mut clips = Vec::new();
    for row in &clip_rows {
        clips.push(upload_bytes(&state, row).await?);
    }
    let limits = state.import_limits.clone();
    let max_work = state.limits.max_bake_work;
    let (key, jobs) = AppState::import_holding(permit, move || -> ApiResult<_> {
        let inputs = BakeInputs::load(&character, &clips, &limits)
            .map_err(|e| ApiError::unimportable(&e.what, &e.source))?;
        let bake = Bake::new(&inputs, params.clone())
            .map_err(|e| ApiError::bad("bad_params", e.to_string()))?;
        let work = bake.work();
        if work > max_work {
            return Err(ApiError::bad(
                "too_much_work",
                format!(
                    "the bake would trace {work} ray-vertex pairs, over the limit of {max_work}: lower poses, eval_poses or samples"
                ),
            ));
        }
        let key = bake_key(&inputs.character_digest, &inputs.clip_digests, &params);
        let graph = bake.graph(state.graph);
        let jobs = graph
            .jobs
            .iter()
            .map(|j| NewJob {
                kind: j.spec.kind().to_owned(),
                spec: serde_json::to_value(&j.spec).expect("specs serialise"),
                work: j.spec.work() as i64,
                deps: j.deps.clone(),
            })
            .collect::<Vec<_>>();
        Ok((key, (jobs, params.canonical())))
    })
    .await??;
    let mut rebakes = None;
    match key_state(&state, &key).await? {
        KeyState::Served(existing) => {
            let location = bake_location(existing.id);
            return Ok((StatusCode::OK, location, Json(view(existing, None))).into_response());
        }
        KeyState::UnderWay(existing) => {
            let location = bake_location(existing.id);
            return Ok((StatusCode::ACCEPTED, location, Json(view(existing, None))).into_response());
        }
        // Baked once, its asset since lost from the blob store: baked
        // again (below), never answered as done, and the answer says so.
        KeyState::Lost(old) => {
            log_line!(
                "key {key}: bake {}'s asset is gone from the blob store; baking it again",
                old.id
            );
            rebakes = Some(old.id);
        }
        KeyState::Unknown => {}
    }
    let (jobs, params) = jobs;
    let bake = state
        .store
        .create_bake(&NewBake {
            key,
            character: req.character,
            clips: req.clips,
            method: method.name().to_owned(),
            params,
            priority: req.priority,
            jobs,
            max_attempts: state.policy.max_attempts,
        })
        .await?;
    state.announce(&bake);
    let location = bake_location(bake.id);
    let view = BakeView {
        rebakes,
        ..view(bake, None)
    };
    Ok((StatusCode::ACCEPTED, location, Json(view)).into_response())
}

/// `Location` of a bake a submit answers with.
fn bake_location(id: i64) -> [(header::HeaderName, String); 1] {
    [(header::LOCATION, format!("/v1/bakes/{id}"))]
}

/// Filters of bake lists.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct ListQuery {
    /// Only bakes of this method.
    method: Option<String>,
    /// At most this many (1 to 1000, default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<i64>,
}

impl ListQuery {
    fn limit(&self) -> ApiResult<i64> {
        match self.limit {
            None => Ok(100),
            Some(n) if (1..=1000).contains(&n) => Ok(n),
            Some(n) => Err(ApiError::bad(
                "bad_query",
                format!("limit must be between 1 and 1000, not {n}"),
            )),
        }
    }
}

#[utoipa::path(get, path = "/v1/bakes", tag = "bakes", params(ListQuery),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Bakes, newest first", body = Vec<BakeView>), Refusals))]
pub(crate) async fn list(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiQuery(q): ApiQuery<ListQuery>,
) -> ApiResult<Json<Vec<BakeView>>> {
    let limit = q.limit()?;
    let bakes = state.store.bakes(None, q.method.as_deref(), limit).await?;
    Ok(Json(bakes.into_iter().map(|b| view(b, None)).collect()))
}

#[utoipa::path(get, path = "/v1/characters/{digest}/bakes", tag = "bakes", params(("digest" = Digest, Path, description = "Character digest"), ListQuery),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Bakes of the character, newest first", body = Vec<BakeView>), Refusals))]
pub(crate) async fn versions(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(digest): ApiPath<String>,
    ApiQuery(q): ApiQuery<ListQuery>,
) -> ApiResult<Json<Vec<BakeView>>> {
    crate::blobs::check_digest(&digest)?;
    let limit = q.limit()?;
    let bakes = state
        .store
        .bakes(Some(&digest), q.method.as_deref(), limit)
        .await?;
    Ok(Json(bakes.into_iter().map(|b| view(b, None)).collect()))
}

async fn find(state: &AppState, id: i64) -> ApiResult<BakeRow> {
    state
        .store
        .bake(id)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no bake {id}")))
}

#[utoipa::path(get, path = "/v1/bakes/{id}", tag = "bakes", params(("id" = i64, Path, description = "Bake id")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The bake with every job", body = BakeView), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn show(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(id): ApiPath<i64>,
) -> ApiResult<Json<BakeView>> {
    let bake = find(&state, id).await?;
    let jobs = state.store.jobs(id).await?;
    Ok(Json(view(bake, Some(jobs))))
}

#[utoipa::path(get, path = "/v1/bakes/{id}/previews", tag = "bakes", params(("id" = i64, Path, description = "Bake id")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The bake's preview images (empty until its preview job has completed)", body = PreviewList), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn previews(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(id): ApiPath<i64>,
) -> ApiResult<Json<PreviewList>> {
    find(&state, id).await?;
    let jobs = state.store.jobs(id).await?;
    let Some(job) = jobs.iter().find(|j| j.kind == "preview") else {
        return Ok(Json(PreviewList {
            state: None,
            previews: Vec::new(),
            unavailable: None,
            pixels: None,
        }));
    };
    let outputs = job.outputs.as_deref().unwrap_or_default();
    let digest_of = |name: &str| {
        outputs
            .iter()
            .find(|o| o.name == name)
            .map(|o| o.digest.clone())
    };
    let mut previews = Vec::new();
    if let Some(list) = digest_of("previews.json") {
        let bytes = state
            .read_blob(&list, None)
            .await?
            .ok_or_else(|| ApiError::Internal(format!("previews.json {list} has no blob")))?;
        let items: Vec<PreviewItem> = serde_json::from_slice(&bytes)
            .map_err(|e| ApiError::Internal(format!("previews.json {list}: {e}")))?;
        for mut item in items {
            item.digest = digest_of(&item.name).ok_or_else(|| {
                ApiError::Internal(format!("preview {} has no output", item.name))
            })?;
            previews.push(item);
        }
    }
    let unavailable = match digest_of(aobake_core::bake::preview::UNAVAILABLE) {
        Some(d) => state
            .read_blob(&d, None)
            .await?
            .map(|b| String::from_utf8_lossy(&b).into_owned()),
        None => None,
    };
    let pixels = match digest_of(aobake_core::bake::screen_space::PIXELS) {
        Some(d) => {
            let bytes = state.read_blob(&d, None).await?.ok_or_else(|| {
                ApiError::Internal(format!("the per-pixel summary {d} has no blob"))
            })?;
            Some(
                serde_json::from_slice(&bytes)
                    .map_err(|e| ApiError::Internal(format!("the per-pixel summary {d}: {e}")))?,
            )
        }
        None => None,
    };
    Ok(Json(PreviewList {
        state: Some(job.state),
        previews,
        unavailable,
        pixels,
    }))
}

#[utoipa::path(get, path = "/v1/bakes/{id}/report", tag = "bakes", params(("id" = i64, Path, description = "Bake id")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The quality report (JSON)", body = Object), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn report(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(id): ApiPath<i64>,
) -> ApiResult<Response> {
    let bake = find(&state, id).await?;
    // A bake that ended without one says so, not "yet".
    let digest = bake.report.ok_or_else(|| {
        ApiError::NotFound(match bake.state {
            crate::store::BakeState::Failed | crate::store::BakeState::Cancelled => {
                format!("bake {id} was {}: it has no report", bake.state.as_str())
            }
            _ => format!("bake {id} has no report yet"),
        })
    })?;
    let bytes = state
        .read_blob(&digest, None)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("report {digest} has no blob")))?;
    Ok((
        [(axum::http::header::CONTENT_TYPE, "application/json")],
        bytes,
    )
        .into_response())
}

#[utoipa::path(patch, path = "/v1/bakes/{id}", tag = "bakes", params(("id" = i64, Path, description = "Bake id")), request_body = PatchBody,
    security(("bearer" = ["submit"])),
    responses((status = 200, description = "Priority set", body = BakeView), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn patch(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiPath(id): ApiPath<i64>,
    Body(body): Body<PatchBody>,
) -> ApiResult<Json<BakeView>> {
    find(&state, id).await?;
    let bake = state.store.set_priority(id, body.priority).await?;
    Ok(Json(view(bake, None)))
}

#[utoipa::path(post, path = "/v1/bakes/{id}/{action}", tag = "bakes", params(("id" = i64, Path, description = "Bake id"), ("action" = String, Path, description = "cancel, pause, resume or retry (a failed or cancelled bake, its unfinished jobs with fresh attempts and its completed jobs whose outputs the blob store lost run again; also a done bake that lost what it serves)")),
    security(("bearer" = ["submit"])),
    responses((status = 200, description = "Done", body = BakeView), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), (status = 409, description = "Conflict: the state forbids it, or the lease is gone", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn control(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiPath((id, action)): ApiPath<(i64, String)>,
) -> ApiResult<Json<BakeView>> {
    let action = match action.as_str() {
        "cancel" => Action::Cancel,
        "pause" => Action::Pause,
        "resume" => Action::Resume,
        "retry" => Action::Retry,
        other => {
            return Err(ApiError::NotFound(format!(
                "no action {other:?}; the actions are cancel, pause, resume, retry"
            )));
        }
    };
    let found = find(&state, id).await?;
    let bake = if action == Action::Retry {
        // Completed jobs whose outputs the blob store lost run again (a
        // done bake that lost what it serves is queued again for them).
        let jobs = state.store.jobs(id).await?;
        let lost = crate::repair::lost_outputs(&*state.blobs, &jobs).await?;
        let again = crate::repair::jobs_to_run_again(&found, &jobs, &lost);
        if !again.is_empty() {
            log_line!(
                "bake {id}: the blob store lost outputs of {} completed job(s); retry runs them again",
                again.len()
            );
        }
        state.store.retry(id, &again).await?
    } else {
        state.store.control(id, action).await?
    };
    state.announce(&bake);
    Ok(Json(view(bake, None)))
}

#[utoipa::path(get, path = "/v1/cache/{key}", tag = "bakes", params(("key" = Digest, Path, description = "Bake key")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The finished bake for this key", body = BakeView), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn cache(
    State(state): State<AppState>,
    _caller: Need<Read>,
    ApiPath(key): ApiPath<String>,
) -> ApiResult<Json<BakeView>> {
    crate::blobs::check_digest(&key)?;
    match key_state(&state, &key).await? {
        KeyState::Served(b) => Ok(Json(view(b, None))),
        // Never a hit for what cannot be fetched.
        KeyState::Lost(b) => Err(ApiError::NotFound(format!(
            "bake {} with key {key} finished, but its asset is gone from the blob store: submit the request again to bake it again",
            b.id
        ))),
        // One under way: say which and how far, so a pipeline waits for it
        // rather than submits again.
        KeyState::UnderWay(b) => {
            let done = crate::state::progress_done(&b);
            Err(ApiError::NotFound(format!(
                "no finished bake for key {key} yet: bake {} with this key is {} ({done} of {} units done)",
                b.id,
                b.state.as_str(),
                b.total_work
            )))
        }
        KeyState::Unknown => Err(ApiError::NotFound(format!(
            "no finished bake for key {key}"
        ))),
    }
}

/// What a bake key stands for now.
enum KeyState {
    /// A finished bake whose asset and report the blob store holds.
    Served(BakeRow),
    /// A bake with the key under way (queued, running or paused).
    UnderWay(BakeRow),
    /// Only finished bakes whose asset or report is gone from the blob
    /// store (an emptied bucket, an expired object): the newest.
    Lost(BakeRow),
    /// No bake with the key.
    Unknown,
}

/// The key's bakes looked at in turn: a finished one is served only when
/// the blob store still holds its asset and report.
async fn key_state(state: &AppState, key: &str) -> ApiResult<KeyState> {
    let bakes = state.store.bakes_for_key(key).await?;
    let mut lost = None;
    for b in &bakes {
        if b.state != crate::store::BakeState::Done {
            continue;
        }
        let mut held = true;
        for digest in [&b.asset, &b.report] {
            held &= match digest {
                Some(d) => state.blobs.len(d).await?.is_some(),
                None => false,
            };
        }
        if held {
            return Ok(KeyState::Served(b.clone()));
        }
        lost.get_or_insert_with(|| b.clone());
    }
    if let Some(b) = bakes
        .iter()
        .find(|b| b.state != crate::store::BakeState::Done)
    {
        return Ok(KeyState::UnderWay(b.clone()));
    }
    Ok(lost.map_or(KeyState::Unknown, KeyState::Lost))
}

#[utoipa::path(post, path = "/v1/keys", tag = "bakes", request_body = BakeRequest,
    security(("bearer" = ["read"])),
    responses((status = 200, description = "The key a bake of this request has (its priority aside), computed without uploading or baking: the digests need not be uploads yet. GET /v1/cache/{key} then answers the finished bake", body = BakeKey), Refusals))]
pub(crate) async fn key(
    _caller: Need<Read>,
    Body(req): Body<BakeRequest>,
) -> ApiResult<Json<BakeKey>> {
    let method: Method = req
        .method
        .parse()
        .map_err(|e: String| ApiError::bad("bad_method", e))?;
    for digest in std::iter::once(&req.character).chain(&req.clips) {
        crate::blobs::check_digest(digest)?;
    }
    let params = BakeParams::with_overrides(method, &req.params)
        .map_err(|e| ApiError::bad("bad_params", e.to_string()))?;
    Ok(Json(BakeKey {
        key: bake_key(&req.character, &req.clips, &params),
        algorithm_version: aobake_core::method::algorithm_version(method),
        params: params.canonical(),
    }))
}

#[utoipa::path(get, path = "/v1/events", tag = "bakes",
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Server-sent events: `bake` with {id, state, done, total} whenever any bake or one of its jobs changes (a job leased, moving or finished; `done` is the view's `progress.done`, running jobs' progress included; an event that says what the bake's last one said is not sent again); a dashboard's bakes list. The stream ends within 5 s of its token being revoked or expiring", content_type = "text/event-stream", body = String), Refusals))]
pub(crate) async fn all_events(
    State(state): State<AppState>,
    caller: Need<Read>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    // Each bake's last event sent: one that says the same again (a job
    // leased at no progress, a heartbeat that moved nothing) is not sent.
    let mut sent: HashMap<i64, crate::state::BakeEvent> = HashMap::new();
    let updates = BroadcastStream::new(state.events.subscribe()).filter_map(move |e| match e {
        Ok(e) => (sent.get(&e.id) != Some(&e)).then(|| {
            let event = bake_event(&e);
            // A bake that ended is forgotten (a tab stays open for days),
            // so its next event (a retry) is sent whatever it says.
            if e.state.is_active() {
                sent.insert(e.id, e);
            } else {
                sent.remove(&e.id);
            }
            Ok(event)
        }),
        // A slow listener that missed events is told to reload.
        Err(_) => {
            sent.clear();
            Some(Ok(Event::default().event("lagged").data("reload")))
        }
    });
    Sse::new(caller.0.while_valid(&state, updates))
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
}

fn bake_event(e: &crate::state::BakeEvent) -> Event {
    Event::default()
        .event("bake")
        .json_data(e)
        .expect("events serialise")
}

#[utoipa::path(get, path = "/v1/bakes/{id}/events", tag = "bakes", params(("id" = i64, Path, description = "Bake id")),
    security(("bearer" = ["read"])),
    responses((status = 200, description = "Server-sent events: `bake` events with id, state, done (the view's `progress.done`) and total, first the bake as it is, then at each change of it or its jobs. The stream ends within 5 s of its token being revoked or expiring; otherwise it stays open after the bake ends (a retry can start it again, and a browser's EventSource reconnects to a closed stream): a follower stops at the state it waits for (done, failed, cancelled)", content_type = "text/event-stream", body = String), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn events(
    State(state): State<AppState>,
    caller: Need<Read>,
    ApiPath(id): ApiPath<i64>,
) -> ApiResult<Sse<impl Stream<Item = Result<Event, Infallible>>>> {
    let rx = state.events.subscribe();
    let bake = find(&state, id).await?;
    let first = crate::state::BakeEvent::of(&bake);
    let initial = tokio_stream::once(Ok(bake_event(&first)));
    // An event that says what the last one said is not sent again.
    let mut last = first;
    let updates = BroadcastStream::new(rx).filter_map(move |e| match e {
        Ok(e) if e.id == id && e != last => {
            let event = bake_event(&e);
            last = e;
            Some(Ok(event))
        }
        _ => None,
    });
    Ok(
        Sse::new(caller.0.while_valid(&state, initial.chain(updates)))
            .keep_alive(KeepAlive::new().interval(Duration::from_secs(15))),
    )
}
