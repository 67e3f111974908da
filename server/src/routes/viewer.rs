//! The dashboard's 3D viewer reads a finished bake from here (core's
//! `bake::viewer` builds both bundles):
//!
//! * `GET /v1/bakes/{id}/viewer`: the character in its bind pose with its
//!   skin, the asset's arrays as the GPU lookups read them (and a vertex
//!   method's static average), the clips, and the WebGL2 program (naga's
//!   GLSL ES 3.00 of `shaders/wgsl/viewer.wgsl` with the family's lookup).
//! * `GET /v1/bakes/{id}/viewer/frames?clip=NAME`: the clip's frames as an
//!   engine computes them (joint matrices, and the model's input: a vertex
//!   method's weights from the runtime, the grids' part poses, a cubemap's
//!   phase), the previews' camera and looks, and the ray-traced truth at
//!   the previews' frames.
//!
//! Both show the character's mesh, which is the studio's source: they need
//! `submit`, as reading the uploaded files themselves does.

use aobake_api::schema::Refusals;
use aobake_core::{
    asset::Container,
    bake::{
        AssetUseError, Bake, BakeInputs, BakeParams, BakedAsset, JobOutput, Output, Panel,
        PreviewModel,
        texel::NO_VIEWER,
        viewer::{self, Bundle, FrameModel, PreviewTruth, ViewerError},
    },
    image::HEAT_MAP,
    method::{Family, Method, vertex::VertexAo},
};
use axum::{
    Router,
    extract::State,
    http::header,
    response::{IntoResponse, Response},
    routing::get,
};
use serde::Deserialize;

use super::uploads::load_upload;
use crate::{
    auth::{Need, Submit},
    error::{ApiError, ApiResult, Problem},
    extract::{ApiPath, ApiQuery},
    state::AppState,
    store::BakeRow,
};

/// The bundles' media type.
const BUNDLE: &str = "application/vnd.aobake.viewer";

pub(super) fn router() -> Router<AppState> {
    Router::new()
        .route("/v1/bakes/{id}/viewer", get(scene))
        .route("/v1/bakes/{id}/viewer/frames", get(frames))
}

/// What both bundles start from: the bake's inputs, parameters and asset.
struct Loaded {
    inputs: BakeInputs,
    params: BakeParams,
    family: Family,
    asset: Vec<u8>,
    /// The outputs of the bake's `preview-truth` jobs.
    truth: Vec<JobOutput>,
}

fn internal(e: impl std::fmt::Display) -> ApiError {
    ApiError::Internal(e.to_string())
}

impl Loaded {
    /// The bake's plan over its inputs.
    fn bake(&self) -> ApiResult<Bake<'_>> {
        Bake::new(&self.inputs, self.params.clone()).map_err(internal)
    }

    /// The asset read against the bake's character.
    fn baked(&self) -> ApiResult<BakedAsset> {
        let container = Container::from_bytes(&self.asset).map_err(internal)?;
        BakedAsset::read(&container, Some(&self.inputs.character))
            .map_err(|e| ApiError::Internal(format!("the bake's asset: {e}")))
    }
}

fn preview_model(baked: &BakedAsset) -> ApiResult<PreviewModel<'_>> {
    match baked.preview_model() {
        // A texel asset: the viewer cannot draw it yet, and says so.
        Ok((PreviewModel::Texel(..), _)) => Err(ApiError::Conflict(NO_VIEWER.into())),
        Ok((model, _)) => Ok(model),
        Err(AssetUseError::Unsupported(why)) => Err(ApiError::Conflict(why)),
        Err(e) => Err(internal(e)),
    }
}

async fn load(state: &AppState, id: i64, truth: bool) -> ApiResult<Loaded> {
    let bake: BakeRow = state
        .store
        .bake(id)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no bake {id}")))?;
    let method: Method = bake
        .method
        .parse()
        .map_err(|e: String| ApiError::Internal(e))?;
    let digest = bake
        .asset
        .clone()
        .ok_or_else(|| ApiError::Conflict(format!("bake {id} has no asset yet")))?;
    // The asset and the inputs are read in the import's turn (see
    // bakes::submit).
    let permit = state.import_permit().await?;
    let asset = state
        .read_blob(&digest, None)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("asset {digest} has no blob")))?;
    let character = load_upload(state, &bake.character, "character").await?;
    let mut clips = Vec::new();
    for c in &bake.clips {
        clips.push(load_upload(state, c, "clips").await?);
    }
    let mut outputs = Vec::new();
    if truth {
        for job in state.store.jobs(id).await? {
            if job.kind != "preview-truth" {
                continue;
            }
            let mut out = JobOutput::default();
            for o in job.outputs.iter().flatten() {
                let bytes = state.read_blob(&o.digest, None).await?.ok_or_else(|| {
                    ApiError::Internal(format!("output {} has no blob", o.digest))
                })?;
                out.outputs.push(Output {
                    name: o.name.clone(),
                    bytes,
                });
            }
            outputs.push(out);
        }
    }
    let limits = state.import_limits.clone();
    let params = bake.params;
    AppState::import_holding(permit, move || -> ApiResult<Loaded> {
        let inputs = BakeInputs::load(&character, &clips, &limits)
            .map_err(|e| ApiError::Internal(format!("bake {id}'s inputs: {e}")))?;
        let params = BakeParams::from_canonical(&params)
            .map_err(|e| ApiError::Internal(format!("bake {id}'s parameters: {e}")))?;
        Ok(Loaded {
            inputs,
            params,
            family: method.family(),
            asset,
            truth: outputs,
        })
    })
    .await?
}

fn bundle(bundle: &Bundle) -> Response {
    (
        [
            (header::CONTENT_TYPE, BUNDLE),
            (header::CACHE_CONTROL, "private, max-age=3600"),
        ],
        bundle.to_bytes(),
    )
        .into_response()
}

fn viewer_error(e: ViewerError) -> ApiError {
    match e {
        ViewerError::NoClip(..) => ApiError::NotFound(e.to_string()),
        ViewerError::TooLarge(_) => ApiError::unprocessable(e.to_string()),
        ViewerError::Job(_) => ApiError::Internal(e.to_string()),
        ViewerError::Unsupported(why) => ApiError::Conflict(why.into()),
    }
}

#[utoipa::path(get, path = "/v1/bakes/{id}/viewer", tag = "bakes", params(("id" = i64, Path, description = "Bake id")),
    security(("bearer" = ["submit"])),
    responses((status = 200, description = "The viewer's scene: an `AOVW` bundle (JSON description, then typed arrays; see docs/engines.md)", content_type = "application/vnd.aobake.viewer", body = crate::routes::uploads::FileBytes), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"), (status = 409, description = "No asset yet", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn scene(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiPath(id): ApiPath<i64>,
) -> ApiResult<Response> {
    let loaded = load(&state, id, false).await?;
    let out = tokio::task::spawn_blocking(move || -> ApiResult<Bundle> {
        let baked = loaded.baked()?;
        let bake = loaded.bake()?;
        let frames = bake.preview_frames().map_err(internal)?;
        let mut scene = viewer::scene(
            &loaded.inputs.character,
            &loaded.inputs.clips,
            preview_model(&baked)?,
            frames.clip.map(|c| c.name.as_str()),
        )
        .map_err(viewer_error)?;
        let family = match loaded.family {
            Family::Vertex => "vertex",
            Family::Grid => "grid",
            Family::Cubemap => "cubemap",
            // preview_model refused it above.
            Family::Texel => return Err(ApiError::Conflict(NO_VIEWER.into())),
        };
        let program = aobake_shaders::export::webgl_viewer(family).map_err(internal)?;
        scene.meta["program"] = serde_json::to_value(program).unwrap_or_default();
        Ok(scene)
    })
    .await
    .map_err(internal)??;
    Ok(bundle(&out))
}

/// Which clip's frames.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub(crate) struct FramesQuery {
    /// The clip's name (the scene's `clips`).
    clip: String,
}

#[utoipa::path(get, path = "/v1/bakes/{id}/viewer/frames", tag = "bakes", params(("id" = i64, Path, description = "Bake id"), FramesQuery),
    security(("bearer" = ["submit"])),
    responses((status = 200, description = "One clip's frames: an `AOVW` bundle", content_type = "application/vnd.aobake.viewer", body = crate::routes::uploads::FileBytes), (status = 404, description = "No such bake or clip", body = Problem, content_type = "application/problem+json"), (status = 409, description = "No asset yet", body = Problem, content_type = "application/problem+json"), Refusals))]
pub(crate) async fn frames(
    State(state): State<AppState>,
    _caller: Need<Submit>,
    ApiPath(id): ApiPath<i64>,
    ApiQuery(query): ApiQuery<FramesQuery>,
) -> ApiResult<Response> {
    let loaded = load(&state, id, true).await?;
    let out = tokio::task::spawn_blocking(move || -> ApiResult<Bundle> {
        let inputs = &loaded.inputs;
        let baked = loaded.baked()?;
        let bake = loaded.bake()?;
        let preview_frames = bake.preview_frames().map_err(internal)?;
        let outputs: Vec<&JobOutput> = loaded.truth.iter().collect();
        let truth = bake.preview_truth_of(&outputs).map_err(internal)?;
        // A vertex method's weights come from the runtime, by node name,
        // as an engine computes them.
        let mut runtime = match loaded.family {
            Family::Vertex => Some(
                VertexAo::from_bytes(&loaded.asset)
                    .map_err(|e| ApiError::Internal(format!("the bake's asset: {e}")))?,
            ),
            Family::Grid | Family::Cubemap | Family::Texel => None,
        };
        let mut model = match (preview_model(&baked)?, runtime.as_mut()) {
            (PreviewModel::Vertex(_), Some(runtime)) => FrameModel::Vertex(runtime),
            (PreviewModel::Grid(model, owners), _) => FrameModel::Grid(model, owners),
            (PreviewModel::Cubemap(model, _), _) => FrameModel::Cubemap(model),
            (PreviewModel::Vertex(_), None) | (PreviewModel::Texel(..), _) => {
                return Err(ApiError::Internal(
                    "a vertex asset of another family".into(),
                ));
            }
        };
        let (mut frames, camera) = viewer::clip_frames(
            &inputs.character,
            &inputs.clips,
            &query.clip,
            &mut model,
            truth.as_ref().map(|truth| PreviewTruth {
                frames: &preview_frames,
                truth,
            }),
        )
        .map_err(viewer_error)?;
        // The previews' looks for this clip's camera, character then
        // ground, as the preview shader's uniform words (the page sets
        // the camera, the eye and the panel itself).
        for (name, ground) in [("shading_character", false), ("shading_ground", true)] {
            let u = aobake_worker::gpu::preview::uniforms(
                &camera,
                1.0,
                &HEAT_MAP,
                Panel::Model,
                ground,
            );
            let words: [u32; 56] = bytemuck::cast(u);
            frames
                .arrays
                .push((name.into(), viewer::Array::U32(words.to_vec())));
        }
        Ok(frames)
    })
    .await
    .map_err(internal)??;
    Ok(bundle(&out))
}
