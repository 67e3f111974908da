//! The texel family's bake (texel-linear; docs/methods/texel.md): the
//! per-vertex family's jobs (`bake::vertex`) run over the texels of the
//! atlas the plan generates (`Plan::receivers`), so sampling, the fit, the
//! unseen-clip folds and the evaluation are the vertex family's, judged
//! per texel. What differs is here: the asset (the vertex model over
//! texels, with its atlas), reading it back, evaluating it at a
//! character's vertices, and its textures as images.

use crate::{
    Character, Pose,
    asset::Container,
    image::FloatImage,
    method::{
        Method,
        texel::{TexelModel, atlas::TexelAtlas},
        vertex::{AssetHeaderFields, Model},
    },
    rig::skeleton::Skeleton,
};

use super::{
    Bake, JobError, JobOutput,
    jobs::{IndexedBlock, decode_with, named, parse},
    preview::{Preview, PreviewModel, Renderer, Subject, frame_poses},
    vertex::{UnseenFold, unseen_model, unseen_output, unseen_texels},
};

/// Why a published texel asset cannot serve a character (`bake::family`
/// turns it into its `AssetUseError`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum Refusal {
    /// Its header or sections do not decode.
    #[error("{0}")]
    Unreadable(String),
    /// It was baked for another character: what differs.
    #[error("{0}")]
    Mismatch(String),
}

/// Why the dashboard's live viewer does not play texel assets yet: it
/// draws per-vertex AO in WebGL2 (the previews render texel assets).
pub const NO_VIEWER: &str = "the dashboard's live viewer does not play texel assets yet (it draws per-vertex AO); the bake's previews show them per pixel, and `aobake preview` renders any clip";

/// A texel bake's atlas and what its textures cost, in its report.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelReport {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Charts.
    pub charts: u32,
    /// Texels that show the surface (the model's columns).
    pub texels: usize,
    /// The share of the atlas's texels whose centre lies on the surface.
    pub utilisation: f64,
    /// Basis textures (the model's weights): per pixel, as many texture
    /// fetches and multiply-adds.
    pub textures: usize,
    /// Their bytes on the GPU: one R16Float layer each, no mipmaps (a
    /// full chain adds a third).
    pub texture_bytes: u64,
}

/// The report's atlas part of a texel bake (none for the other families).
pub(super) fn report(receivers: &super::Receivers, model: &Model) -> Option<TexelReport> {
    let super::Receivers::Texels(atlas) = receivers else {
        return None;
    };
    let a = &atlas.atlas;
    let textures = model.weight_count();
    Some(TexelReport {
        width: a.width,
        height: a.height,
        charts: a.charts,
        texels: atlas.texels.len(),
        utilisation: atlas.texels.utilisation(),
        textures,
        texture_bytes: 2 * textures as u64 * u64::from(a.width) * u64::from(a.height),
    })
}

/// A texel bake's asset: `model` over the texels of `atlas`.
pub(super) fn encode(
    method: Method,
    model: Model,
    atlas: &TexelAtlas,
    header: AssetHeaderFields,
    skeleton: &Skeleton,
) -> Vec<u8> {
    TexelModel {
        method,
        model,
        atlas: atlas.layout(),
    }
    .to_container(header, skeleton)
    .to_bytes()
}

/// The texel model of an asset [`encode`] wrote.
pub(super) fn decode(bytes: &[u8]) -> Result<TexelModel, JobError> {
    decode_with(bytes, |c| TexelModel::from_container(c, None))
}

/// A published texel asset read and, with `character`, checked against
/// it: its joints, and an atlas over its vertices and triangles.
pub(crate) fn read(
    container: &Container,
    character: Option<&Character>,
) -> Result<(TexelModel, crate::method::vertex::AssetHeader), Refusal> {
    let (model, header) = TexelModel::from_container(container, None)
        .map_err(|e| Refusal::Unreadable(e.to_string()))?;
    if let Some(c) = character {
        let mismatch = |e: String| {
            Refusal::Mismatch(format!(
                "{e} (the asset's character is {})",
                header.character
            ))
        };
        if model.atlas.triangles.len() != c.triangles.len()
            || model
                .atlas
                .xref
                .iter()
                .any(|&x| x as usize >= c.vertex_count())
        {
            return Err(mismatch(format!(
                "it was baked for another character: this one has {} triangles and {} vertices, the asset's atlas covers {} triangles",
                c.triangles.len(),
                c.vertex_count(),
                model.atlas.triangles.len()
            )));
        }
        let corners_match = model
            .atlas
            .triangles
            .iter()
            .zip(&c.triangles)
            .all(|(a, t)| (0..3).all(|k| model.atlas.xref[a[k] as usize] == t[k]));
        if !corners_match {
            return Err(mismatch(
                "the asset's atlas is over other triangles: it was baked for another character"
                    .into(),
            ));
        }
        // The joints the weights read (the vertex check's, without its
        // vertex count: the columns are texels).
        let nodes = c.skeleton.nodes.len();
        if let Model::VertexLinear(layout, _) = &model.model
            && layout.nodes().any(|n| n >= nodes)
        {
            return Err(mismatch(
                "the asset reads joints the character does not have: it was baked for another character"
                    .into(),
            ));
        }
    }
    Ok((model, header))
}

/// AO at each vertex of `character` in `pose`, as the texel shader reads
/// it there: the basis textures weighted and summed, filtered at the UV
/// of the vertex's first atlas vertex that a triangle uses, then clamped
/// (0 for a vertex of no triangle).
pub(super) fn vertex_ao(model: &TexelModel, character: &Character, pose: &Pose) -> Vec<f32> {
    let weights = model.model.weights(&character.skeleton, &pose.locals);
    let atlas = &model.atlas;
    // A model without textures (sparse rows): its clamped values, dilated.
    let image = model
        .texture(&weights)
        .unwrap_or_else(|_| atlas.image(&model.model.evaluate_weights(&weights)));
    // Only atlas vertices a triangle uses (the glTF export writes those).
    let mut used = vec![false; atlas.xref.len()];
    atlas
        .triangles
        .iter()
        .flatten()
        .for_each(|&a| used[a as usize] = true);
    let mut uv_of: Vec<Option<[f32; 2]>> = vec![None; character.vertex_count()];
    for ((&x, &uv), _) in atlas
        .xref
        .iter()
        .zip(&atlas.uvs)
        .zip(&used)
        .filter(|(_, u)| **u)
    {
        let slot = &mut uv_of[x as usize];
        if slot.is_none() {
            *slot = Some(uv);
        }
    }
    uv_of
        .iter()
        .map(|uv| {
            uv.map_or(0.0, |uv| {
                aobake_runtime::method::texel::bilinear(&image, atlas.width, atlas.height, uv)
                    .clamp(0.0, 1.0)
            })
        })
        .collect()
}

/// The textures of a texel asset: one image (`texel-ao.exr`) whose
/// channel `w{k}` is the model's coefficient row k scattered into the
/// atlas and dilated, exactly what an engine samples; per pixel
/// `ao = clamp(Σ_k w_k · w{k}, 0, 1)` with the pose's weights.
/// A model whose coefficients are not dense rows says why it has none.
pub(super) fn images(model: &TexelModel) -> Result<Vec<FloatImage>, String> {
    let atlas = &model.atlas;
    let basis = model.basis().map_err(|e| e.to_string())?;
    let k = basis.len();
    let channels = basis
        .into_iter()
        .enumerate()
        .map(|(k, image)| (format!("w{k:02}"), image))
        .collect();
    Ok(vec![FloatImage {
        file: "texel-ao.exr".into(),
        layer: "texel".into(),
        comment: format!(
            "aobake {}: {k} coefficient textures over a {} x {} atlas (the asset's ATUV texture coordinates, v down); per pixel ao = clamp(sum_k weight_k x w_k, 0, 1) with the pose's weights from aobake-runtime's Model::weights",
            model.method, atlas.width, atlas.height
        ),
        width: atlas.width as usize,
        height: atlas.height as usize,
        channels,
    }])
}

/// The kind (in `previews.json`) of a still of a clip a texel bake's
/// unseen-clip fold left out, drawn with the fold's model.
pub const UNSEEN_KIND: &str = "unseen";

/// A texel bake's unseen-clip folds judged per pixel: for each fold's
/// `unseen` job among `deps`, stills of the clip it left out
/// ([`UnseenFold::stills`]) drawn with the fold's model, which never saw
/// that clip, and judged per pixel beside the fold's static average, the
/// texel floor, the per-vertex floor and GTAO. Named
/// `unseen-{fold}-{i}.png`, of kind [`UNSEEN_KIND`]. `model` is the bake's
/// own texel model, whose atlas the folds share. A fold whose model takes
/// more weights than GPUs hold texture layers is left out.
pub(super) fn unseen_previews(
    bake: &Bake<'_>,
    deps: &[&JobOutput],
    model: &TexelModel,
    atlas: &TexelAtlas,
    surface: crate::trace::SurfaceParams,
    renderer: &mut dyn Renderer,
) -> Result<Vec<Preview>, JobError> {
    let character = &bake.inputs.character;
    let texels = atlas.texels.len();
    let mut previews = Vec::new();
    for (fold, &c) in bake.plan.fold_clips().iter().enumerate() {
        let name = unseen_output(fold);
        let Some(out) = deps.iter().find(|d| d.get(&name).is_some()) else {
            continue;
        };
        let info: UnseenFold = parse(named(out, &name)?)?;
        let clip = &bake.inputs.clips[c];
        let folded = decode(named(out, &unseen_model(fold))?)?;
        let block = IndexedBlock::from_bytes(named(out, &unseen_texels(fold))?, texels)?.block;
        if info.clip != clip.name
            || folded.atlas != model.atlas
            || block.poses() != 1 + info.stills.len()
        {
            return Err(JobError::Invalid(format!(
                "unseen fold {fold} does not match the bake: clip {:?} (the plan's {:?}), {} rows for {} stills, {} atlas",
                info.clip,
                clip.name,
                block.poses(),
                info.stills.len(),
                if folded.atlas == model.atlas {
                    "the same"
                } else {
                    "another"
                }
            )));
        }
        if folded.model.weight_count() > crate::method::texel::MAX_TEXTURES {
            continue;
        }
        let subject = Subject {
            static_texels: Some(block.row(0)),
            left_out: Some(&clip.name),
            ..Subject::new(character, PreviewModel::Texel(&folded, atlas), surface)
        };
        let ground = subject.camera(Some(clip)).ground();
        let poses = frame_poses(character, Some(clip), &info.stills);
        // The vertices and the ground traced here; the texels were traced
        // with the held-out poses (the same rays and seed).
        let mut truth = subject.tracing().trace(character, &poses, &ground, None)?;
        truth.texels = Some(crate::trace::AoBlock {
            vertices: texels,
            values: block.values[texels..].to_vec(),
        });
        let stills = subject.stills(Some(clip), &info.stills, Some(truth), renderer)?;
        for (i, mut p) in stills.into_iter().enumerate() {
            p.info.name = format!("unseen-{fold}-{i}.png");
            p.info.kind = UNSEEN_KIND.into();
            previews.push(p);
        }
    }
    Ok(previews)
}
