//! What the dashboard's 3D viewer loads: a bake's character in its bind
//! pose with its skin, the asset's arrays as the GPU lookups read them
//! (the runtime's [`GpuArrays`], [`GridGpu`], [`CubemapGpu`]) and where
//! the page binds them, and per clip the frames an engine would compute at
//! run time: each joint's `world_from_bind` matrix and the model's
//! per-frame input ([`FrameModel`]): a vertex method's weights from the
//! clip's local transforms through the runtime's [`VertexAo`] (by node
//! name, as an engine calls it), the grids' part poses, or a cubemap's
//! phase. The clip the previews traced plays at their frames (stills and
//! animation), each with its ground truth and the model's error there; any
//! other clip plays every 1/30 s without truth.
//!
//! Both are [`Bundle`]s: a JSON description and typed arrays in one
//! binary (`AOVW`), which the page reads without copying.

use glam::Vec3;
use serde::Serialize;
use serde_json::{Value, json};

use crate::{
    Character,
    asset::metrics::FrameError,
    method::{
        cubemap::{gpu::CubemapGpu, model::CubemapModel},
        grid::{base::Receiver, gpu::GridGpu, model::GridModel},
        vertex::{VertexAo, form::GpuArrays},
    },
    rig::{
        clip::Clip,
        pose::{Pose, PosedMesh},
    },
};

use super::{
    JobError,
    preview::{Camera, FrameTruth, Ground, PreviewFrames, PreviewModel, camera, grid_weights},
};

/// Frames per second of a clip's frames.
pub const FPS: f32 = 30.0;
/// Most frames of one clip: a longer clip is sampled more sparsely.
pub const MAX_FRAMES: usize = 600;
/// The bundle's magic.
pub const MAGIC: &[u8; 4] = b"AOVW";
/// The bundle's version.
pub const VERSION: u32 = 1;

/// One typed array of a [`Bundle`].
#[derive(Debug, Clone, PartialEq)]
pub enum Array {
    /// 32-bit floats.
    F32(Vec<f32>),
    /// 32-bit unsigned integers.
    U32(Vec<u32>),
}

impl Array {
    fn kind(&self) -> &'static str {
        match self {
            Self::F32(_) => "f32",
            Self::U32(_) => "u32",
        }
    }

    fn len(&self) -> usize {
        match self {
            Self::F32(v) => v.len(),
            Self::U32(v) => v.len(),
        }
    }
}

/// A JSON description and named typed arrays, written as one binary:
///
/// ```text
/// "AOVW"  u32 version  u32 json_bytes  json (padded with spaces to 4 bytes)
/// arrays, little-endian, one after another
/// ```
///
/// The JSON is the description with `arrays` added: per name its `type`
/// (`f32` or `u32`), `offset` (bytes from the end of the JSON, where the
/// arrays start, a multiple of 4 like that start) and `count`.
#[derive(Debug, Clone, PartialEq)]
pub struct Bundle {
    /// The description (a JSON object).
    pub meta: Value,
    /// The arrays, by name.
    pub arrays: Vec<(String, Array)>,
}

impl Bundle {
    /// The binary.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut meta = self.meta.clone();
        let mut table = serde_json::Map::new();
        let data: usize = self.arrays.iter().map(|(_, a)| 4 * a.len()).sum();
        let mut start = 0usize;
        for (name, array) in &self.arrays {
            table.insert(
                name.clone(),
                json!({"type": array.kind(), "offset": start, "count": array.len()}),
            );
            start += 4 * array.len();
        }
        meta["arrays"] = Value::Object(table);
        let mut text = serde_json::to_string(&meta).unwrap_or_default();
        while !(12 + text.len()).is_multiple_of(4) {
            text.push(' ');
        }
        let header_len = 12 + text.len();
        let mut out = Vec::with_capacity(header_len + data);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(text.as_bytes());
        for (_, array) in &self.arrays {
            match array {
                Array::F32(v) => v
                    .iter()
                    .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
                Array::U32(v) => v
                    .iter()
                    .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            }
        }
        out
    }
}

fn flat3(v: &[Vec3]) -> Vec<f32> {
    v.iter().flat_map(|p| p.to_array()).collect()
}

/// Why a bake cannot be shown in the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The asset's arrays do not fit 32-bit offsets.
    #[error("the asset is too large for the viewer: {0}")]
    TooLarge(String),
    /// No clip of that name.
    #[error("no clip named {0:?} (the bake's clips: {1})")]
    NoClip(String, String),
    /// The bake's jobs disagree with its inputs.
    #[error(transparent)]
    Job(#[from] JobError),
    /// The viewer cannot draw this model.
    #[error("{0}")]
    Unsupported(&'static str),
}

/// Texels per row of the data textures (WebGL2's smallest
/// `MAX_TEXTURE_SIZE`; `aobake_shaders::VS_TEXTURE_WIDTH`).
pub const TEXTURE_WIDTH: u32 = 2048;

fn too_large(e: impl std::fmt::Display) -> ViewerError {
    ViewerError::TooLarge(e.to_string())
}

/// The viewer's scene of a bake of `model`: `character` in its bind pose,
/// its skin, the clips by name (`preview` is the previews' clip), and the
/// model's arrays with the bindings the page gives them (`uniforms` and
/// `textures`: a WGSL binding and an array's name each; `frame`: where a
/// frame's input goes), and which surfaces the model shades. A vertex
/// method's also holds its static average (the model averaged over the
/// clips' frames, as the glTF export's `_AO`).
pub fn scene(
    character: &Character,
    clips: &[Clip],
    model: PreviewModel<'_>,
    preview: Option<&str>,
) -> Result<Bundle, ViewerError> {
    let k = character.influences;
    let mut skin = Vec::with_capacity(2 * k * character.vertex_count());
    for v in 0..character.vertex_count() {
        skin.extend_from_slice(&character.joint_indices[v * k..(v + 1) * k]);
        skin.extend(
            character.joint_weights[v * k..(v + 1) * k]
                .iter()
                .map(|w| w.to_bits()),
        );
    }
    let mut meta = json!({
        "method": model.method().name(),
        "vertices": character.vertex_count(),
        "triangles": character.triangles.len(),
        "influences": k,
        "joints": character.joints.len(),
        "texture_width": TEXTURE_WIDTH,
        // Where the viewer's GPU skinning differs from the previews' CPU
        // skinning: morph targets are not applied, and normals the file
        // lacked are the bind pose's, skinned, not recomputed per frame.
        "morphs": !character.morphs.is_empty(),
        "computed_normals": character.primitives.iter().any(|p| p.computed_normals),
        "clips": clips.iter().map(|c| json!({"name": c.name, "duration": c.duration})).collect::<Vec<_>>(),
        "preview_clip": preview,
    });
    let mut arrays: Vec<(String, Array)> = vec![
        ("positions".into(), Array::F32(flat3(&character.positions))),
        ("normals".into(), Array::F32(flat3(&character.normals))),
        (
            "indices".into(),
            Array::U32(character.triangles.iter().flatten().copied().collect()),
        ),
        ("skin".into(), Array::U32(skin)),
    ];
    let layout = vec![TEXTURE_WIDTH, 1, 1, 0];
    let family = match model {
        PreviewModel::Vertex(model) => {
            let gpu = GpuArrays::new(model.form()).map_err(too_large)?;
            let (static_ao, static_frames) =
                crate::asset::gltf::static_ao(model, &character.skeleton, clips);
            meta["static_frames"] = static_frames.into();
            let blocks = gpu.blocks.len() as u32;
            let vs_params = vec![
                gpu.vertices,
                blocks,
                u32::from(gpu.sparse),
                TEXTURE_WIDTH,
                1,
                1,
                0,
                0,
            ];
            arrays.extend([
                ("static_ao".into(), Array::F32(static_ao)),
                ("vs_params".into(), Array::U32(vs_params)),
                (
                    "blocks".into(),
                    Array::U32(if gpu.blocks.is_empty() {
                        vec![0; 8]
                    } else {
                        gpu.blocks.iter().flatten().copied().collect()
                    }),
                ),
                ("coefficients".into(), Array::U32(gpu.coefficients)),
                ("maps".into(), Array::U32(gpu.maps)),
                ("sparse_rows".into(), Array::U32(gpu.sparse_rows)),
            ]);
            json!({
                "family": "vertex",
                "uniforms": [{"binding": 0, "array": "vs_params"}],
                "textures": [
                    {"binding": 1, "array": "blocks"},
                    {"binding": 2, "array": "coefficients"},
                    {"binding": 3, "array": "maps"},
                    {"binding": 5, "array": "sparse_rows"},
                ],
                "frame": {"kind": "texture", "binding": 4, "floats": gpu.weights},
                "model_on": {"character": true, "ground": false},
            })
        }
        PreviewModel::Texel(..) => {
            return Err(ViewerError::Unsupported(super::texel::NO_VIEWER));
        }
        PreviewModel::Grid(model, owners) => {
            let gpu = GridGpu::new(model).map_err(too_large)?;
            let params = vec![
                gpu.parts(),
                0,
                0,
                gpu.cones,
                gpu.tclip_resolution,
                gpu.tclip_offset,
                gpu.base,
                gpu.ground_gain,
            ];
            let mut infos: Vec<u32> = gpu.infos.iter().flatten().copied().collect();
            infos.resize(infos.len().max(4), 0);
            arrays.extend([
                ("grid_params".into(), Array::U32(params)),
                ("layout".into(), Array::U32(layout)),
                ("infos".into(), Array::U32(infos)),
                ("cells".into(), Array::U32(gpu.cells)),
                (
                    "receivers".into(),
                    Array::U32(grid_receivers(model, owners)),
                ),
            ]);
            json!({
                "family": "grid",
                "uniforms": [{"binding": 0, "array": "grid_params"}, {"binding": 4, "array": "layout"}],
                "textures": [
                    {"binding": 1, "array": "infos"},
                    {"binding": 2, "array": "cells"},
                    {"binding": 5, "array": "receivers"},
                ],
                "frame": {"kind": "texture", "binding": 3, "floats": 32 * gpu.infos.len()},
                "model_on": {"character": true, "ground": true},
            })
        }
        PreviewModel::Cubemap(model, _) => {
            let gpu = CubemapGpu::new(model).map_err(too_large)?;
            let mut params: Vec<u32> = gpu
                .centre
                .iter()
                .chain(&gpu.radii)
                .map(|x| x.to_bits())
                .collect();
            // The viewer shades only the ground with a cubemap: on_ground 1.
            params.extend([
                gpu.resolution,
                gpu.shells,
                gpu.times,
                gpu.encoding,
                0,
                0,
                0,
                1,
            ]);
            arrays.extend([
                ("cubemap_params".into(), Array::U32(params)),
                ("layout".into(), Array::U32(layout)),
                ("texels".into(), Array::U32(gpu.texels)),
                ("ground".into(), Array::U32(gpu.ground)),
            ]);
            json!({
                "family": "cubemap",
                "uniforms": [{"binding": 0, "array": "cubemap_params"}, {"binding": 2, "array": "layout"}],
                "textures": [{"binding": 1, "array": "texels"}, {"binding": 4, "array": "ground"}],
                "frame": {"kind": "phase", "floats": 1},
                "model_on": {"character": false, "ground": true},
            })
        }
    };
    meta["model"] = family;
    Ok(Bundle { meta, arrays })
}

/// A model's run time per frame, as an engine drives it.
#[derive(Debug)]
pub enum FrameModel<'a> {
    /// A vertex method through the runtime (joints by node name).
    Vertex(&'a mut VertexAo),
    /// Grids: each part's pose from the joint matrices; the character's
    /// vertices on their parts (`owners`, `u32::MAX` for none).
    Grid(&'a GridModel, &'a [u32]),
    /// A cubemap at the frame's phase.
    Cubemap(&'a CubemapModel),
}

impl FrameModel<'_> {
    /// What the page uploads for a frame: a vertex method's weights, the
    /// parts' poses (`grid_weights`), or a cubemap's phase.
    fn input(&mut self, character: &Character, pose: &Pose, time: f32) -> Vec<f32> {
        match self {
            Self::Vertex(runtime) => {
                runtime.reset();
                for (node, local) in character.skeleton.nodes.iter().zip(&pose.locals) {
                    if let Some(n) = node.name.as_deref().and_then(|name| runtime.node(name)) {
                        runtime.set_local(n, *local);
                    }
                }
                runtime.weights()
            }
            Self::Grid(model, _) => grid_weights(model, &character.joint_matrices(pose)),
            Self::Cubemap(model) => vec![model.layout.phase(time)],
        }
    }

    /// The model's AO where it shades: on the character's vertices (posed
    /// as `posed`) and on `ground`'s points, at the frame just given to
    /// [`Self::input`].
    fn ao(
        &mut self,
        character: &Character,
        pose: &Pose,
        posed: &PosedMesh,
        ground: &Ground,
        time: f32,
    ) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
        match self {
            Self::Vertex(runtime) => (Some(runtime.evaluate()), None),
            Self::Grid(model, owners) => {
                let poses = model.poses(&character.joint_matrices(pose));
                let on_character = (0..posed.positions.len())
                    .map(|v| {
                        let owner = owners.get(v).copied().unwrap_or(u32::MAX);
                        model.ao(
                            &poses,
                            posed.positions[v],
                            posed.normals[v],
                            Receiver::vertex(v, owner),
                        )
                    })
                    .collect();
                let on_ground = ground
                    .positions
                    .iter()
                    .map(|&p| model.ao(&poses, p, Vec3::Y, Receiver::Ground))
                    .collect();
                (Some(on_character), Some(on_ground))
            }
            Self::Cubemap(model) => {
                let phase = model.layout.phase(time);
                (
                    None,
                    Some(
                        ground
                            .positions
                            .iter()
                            .map(|&p| model.ground_ao(p, phase))
                            .collect(),
                    ),
                )
            }
        }
    }
}

/// RMSE and worst difference of `got` against `want`.
fn error(got: &[f32], want: &[f32]) -> Value {
    let worst = got
        .iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    json!({"rmse": FrameError::of(got, want).rmse, "max": worst})
}

/// The times of a clip's frames, sorted: the previews' frames where they
/// traced this clip (`traced`: their stills and their animation's frames,
/// every one with truth, so the ground and the error do not come and go as
/// it plays), else every `1 / FPS` seconds (at most [`MAX_FRAMES`], spread
/// evenly).
fn frame_times(clip: &Clip, traced: &[f32]) -> Vec<f32> {
    let mut times = if traced.is_empty() {
        clip.frame_times(FPS)
    } else {
        traced.to_vec()
    };
    if times.len() > MAX_FRAMES {
        let step = (times.len() - 1) as f64 / (MAX_FRAMES - 1) as f64;
        times = (0..MAX_FRAMES)
            .map(|i| times[((i as f64 * step).round() as usize).min(times.len() - 1)])
            .collect();
    }
    times.sort_by(f32::total_cmp);
    times.dedup_by(|a, b| a.to_bits() == b.to_bits());
    times
}

/// The previews' frames and their truth, when the clip is theirs.
#[derive(Debug, Clone, Copy)]
pub struct PreviewTruth<'a> {
    /// The previews' frames (their clip, stills and animation).
    pub frames: &'a PreviewFrames<'a>,
    /// The ray-traced truth of every one of them, in
    /// [`PreviewFrames::times`]' order.
    pub truth: &'a FrameTruth,
}

/// A camera as the page reads it.
#[derive(Debug, Serialize)]
struct CameraView {
    eye: [f32; 3],
    target: [f32; 3],
    fov_y: f32,
    near: f32,
    far: f32,
    ground_y: f32,
    ground_half_extent: f32,
}

impl From<Camera> for CameraView {
    fn from(c: Camera) -> Self {
        Self {
            eye: c.eye.to_array(),
            target: c.target.to_array(),
            fov_y: c.fov_y,
            near: c.near,
            far: c.far,
            ground_y: c.ground_y,
            ground_half_extent: c.ground_half_extent,
        }
    }
}

/// The frames of `clip` (of `clips`) for the viewer: per frame its time,
/// every joint's `world_from_bind` (16 floats each, column-major) and the
/// model's input from `model`; the camera and ground the previews use for
/// that clip (returned too); and where `truth` covers the clip, the traced
/// AO of the character and the ground at those frames with the model's
/// error where it shades.
pub fn clip_frames(
    character: &Character,
    clips: &[Clip],
    clip: &str,
    model: &mut FrameModel<'_>,
    truth: Option<PreviewTruth<'_>>,
) -> Result<(Bundle, Camera), ViewerError> {
    let Some(clip) = clips.iter().find(|c| c.name == clip) else {
        let names: Vec<&str> = clips.iter().map(|c| c.name.as_str()).collect();
        return Err(ViewerError::NoClip(clip.to_owned(), names.join(", ")));
    };
    let truth = truth.filter(|t| t.frames.clip.is_some_and(|c| c.name == clip.name));
    let truth_times = truth.map(|t| t.frames.times()).unwrap_or_default();
    let times = frame_times(clip, &truth_times);
    let skeleton = &character.skeleton;
    let camera = camera(character, Some(clip));
    let ground = camera.ground();
    let mut palettes = Vec::with_capacity(times.len() * 16 * character.joints.len());
    let mut inputs = Vec::new();
    let (mut traced, mut ground_traced) = (Vec::new(), Vec::new());
    let mut frames_truth = Vec::with_capacity(times.len());
    let mut errors = Vec::new();
    for &t in &times {
        let pose = Pose::sample(skeleton, clip, t);
        palettes.extend(
            character
                .joint_matrices(&pose)
                .iter()
                .flat_map(|m| m.to_cols_array()),
        );
        inputs.extend(model.input(character, &pose, t));
        let row = truth_times.iter().position(|s| s.to_bits() == t.to_bits());
        frames_truth.push(row.map(|_| errors.len()));
        if let (Some(row), Some(truth)) = (row, truth) {
            let want = truth.truth.character.row(row);
            let want_ground = truth.truth.ground.row(row);
            let posed = character.skin(&pose);
            let (on_character, on_ground) = model.ao(character, &pose, &posed, &ground, t);
            errors.push(json!({
                "time": t,
                "character": on_character.map(|a| error(&a, want)),
                "ground": on_ground.map(|a| error(&a, want_ground)),
            }));
            traced.extend_from_slice(want);
            ground_traced.extend_from_slice(want_ground);
        }
    }
    // The page opens on the previews' first still where it has one.
    let start = truth
        .and_then(|t| t.frames.stills.first())
        .and_then(|s| times.iter().position(|t| t.to_bits() == s.to_bits()))
        .unwrap_or(0);
    let meta = json!({
        "clip": clip.name,
        "duration": clip.duration,
        "start": start,
        "times": times,
        "truth": frames_truth,
        "errors": errors,
        "camera": CameraView::from(camera),
        "ground_vertices": ground.positions.len(),
        "joints": character.joints.len(),
        "inputs": inputs.len() / times.len().max(1),
    });
    let bundle = Bundle {
        meta,
        arrays: vec![
            ("palettes".into(), Array::F32(palettes)),
            ("inputs".into(), Array::F32(inputs)),
            ("truth".into(), Array::F32(traced)),
            ("ground_truth".into(), Array::F32(ground_traced)),
            (
                "ground_positions".into(),
                Array::F32(flat3(&ground.positions)),
            ),
            (
                "ground_indices".into(),
                Array::U32(ground.triangles.iter().flatten().copied().collect()),
            ),
        ],
    };
    Ok((bundle, camera))
}

/// The viewer's `receivers` for a grid asset (viewer_grid.wgsl's binding
/// 5): the base's ground texture as `common/ground_texture.wgsl` reads it
/// (a lone 0 word and four unused ones without a base), the vertex count,
/// then per vertex its part (`u32::MAX`: none) and its base offset (f32
/// bits).
fn grid_receivers(model: &GridModel, owners: &[u32]) -> Vec<u32> {
    let mut words = match &model.base {
        Some(b) => b.ground.gpu_words(),
        None => vec![0; 5],
    };
    words.push(owners.len() as u32);
    for (i, &owner) in owners.iter().enumerate() {
        let offset = model.offset(Receiver::vertex(i, owner), Vec3::ZERO);
        words.extend([owner, offset.to_bits()]);
    }
    words
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundle_lays_arrays_out_aligned_where_its_json_says() {
        let bundle = Bundle {
            meta: json!({"what": "a test"}),
            arrays: vec![
                ("a".into(), Array::F32(vec![1.5, -2.0])),
                ("b".into(), Array::U32(vec![7, 8, 9])),
            ],
        };
        let bytes = bundle.to_bytes();
        assert_eq!(&bytes[..4], MAGIC);
        let json_len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
        assert_eq!((12 + json_len) % 4, 0);
        let meta: Value = serde_json::from_slice(&bytes[12..12 + json_len]).unwrap();
        assert_eq!(meta["what"], "a test");
        let at = |name: &str, i: usize| {
            let o =
                12 + json_len + meta["arrays"][name]["offset"].as_u64().unwrap() as usize + 4 * i;
            assert_eq!(o % 4, 0);
            <[u8; 4]>::try_from(&bytes[o..o + 4]).unwrap()
        };
        assert_eq!(meta["arrays"]["b"]["count"], 3);
        assert_eq!(f32::from_le_bytes(at("a", 1)), -2.0);
        assert_eq!(u32::from_le_bytes(at("b", 2)), 9);
        assert_eq!(bytes.len(), 12 + json_len + 4 * 5);
    }
}
