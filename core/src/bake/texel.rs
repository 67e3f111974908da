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
        vertex::{AssetHeaderFields, FormRef, Model},
    },
    rig::skeleton::Skeleton,
};

use super::{JobError, jobs::decode_with};

/// Why a published texel asset cannot serve a character (`bake::family`
/// turns it into its `AssetUseError`).
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Refusal {
    /// Its header or sections do not decode.
    Unreadable(String),
    /// It was baked for another character: what differs.
    Mismatch(String),
}

/// Why a texel bake has no previews yet: the preview renderer draws
/// per-vertex AO, and texel assets need their textures sampled per pixel.
pub const NO_PREVIEWS: &str = "texel assets are not previewed yet: the preview renderer draws per-vertex AO (see docs/methods/texel.md; `aobake bench texel` judges texel-linear per pixel)";

/// The most values `images` writes (4 GB of f32): 33 textures of 4096²
/// fit; a hostile header's 4097 cannot ask for hundreds of GB.
const MAX_EXPORT_VALUES: u64 = 1 << 30;

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
pub(super) fn read(
    container: &Container,
    character: Option<&Character>,
) -> Result<(TexelModel, crate::method::vertex::AssetHeader), Refusal> {
    let (model, header) =
        TexelModel::from_container(container, character.map(|c| c.vertex_count()))
            .map_err(|e| Refusal::Unreadable(e.to_string()))?;
    if let Some(c) = character {
        let mismatch =
            |e: String| Refusal::Mismatch(format!("{e} (character {})", header.character));
        if model.atlas.triangles.len() != c.triangles.len() {
            return Err(mismatch(format!(
                "the character has {} triangles but the asset's atlas {}",
                c.triangles.len(),
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

/// AO at each vertex of `character` in `pose`, as an engine's sampler
/// reads the texel model's texture there (at the UV of the vertex's first
/// atlas vertex; 0 for a vertex of no triangle).
pub(super) fn vertex_ao(model: &TexelModel, character: &Character, pose: &Pose) -> Vec<f32> {
    let values = model.model.evaluate(&character.skeleton, &pose.locals);
    let atlas = &model.atlas;
    let image = atlas.image(&values);
    let mut uv_of: Vec<Option<[f32; 2]>> = vec![None; character.vertex_count()];
    for (&x, &uv) in atlas.xref.iter().zip(&atlas.uvs) {
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
    let FormRef::Dense(form) = model.model.form() else {
        return Err(
            "a sparse texel model has no textures to export (bake with linear.threshold 0)".into(),
        );
    };
    let atlas = &model.atlas;
    let values = form.weight_count() as u64 * u64::from(atlas.width) * u64::from(atlas.height);
    if values > MAX_EXPORT_VALUES {
        return Err(format!(
            "{} textures of {} × {} texels are {values} values, more than the {MAX_EXPORT_VALUES} an export writes",
            form.weight_count(),
            atlas.width,
            atlas.height
        ));
    }
    let mut channels = Vec::new();
    let mut k = 0;
    for block in &form.blocks {
        if block.map.is_some() {
            return Err("a texel model with clustered columns has no textures to export".into());
        }
        for row in block.coefficients.chunks_exact(block.columns) {
            let values: Vec<f32> = row.iter().map(|c| c.to_f32()).collect();
            channels.push((format!("w{k:02}"), atlas.image(&values)));
            k += 1;
        }
    }
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
