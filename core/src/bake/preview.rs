//! Previews: what a person looks at to judge a bake. Core prepares the
//! frames (the posed character, its ray-traced ground truth, the model's
//! per-pose weights, one camera framed on the whole clip) and lays the
//! rendered panels out into PNGs; the drawing itself, and the model's AO
//! on the GPU, belong to a [`Renderer`], which the worker implements with
//! wgpu (core knows no GPU, DESIGN §2).
//!
//! * A **still** is one clip time as a row of four panels: the ray-traced
//!   ground truth, the baked model, the screen-space baseline (GTAO, what
//!   an engine computes without a bake; [`super::screen_space`]), and the
//!   model's error (model − truth: too dark in red, too bright in blue, as
//!   Kroon shows it) with its legend. Its [`PreviewInfo`] carries the
//!   baseline's and the model's errors against per-pixel ray-traced AO,
//!   and what each costs per frame on the adapter.
//! * An **animation** is an APNG of a whole clip, the model beside the
//!   ground truth.
//!
//! The images depend only on the inputs (no jitter, no clock): the same
//! adapter draws the same bytes. Render times go into [`PreviewInfo`],
//! never into an image.

use crate::image::{HEAT_MAP, HeatMap, Image, encode_apng, encode_image};
use std::time::Instant;

use glam::{Mat4, Vec3};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    Character,
    method::{
        Method,
        cubemap::model::CubemapModel,
        grid::model::GridModel,
        texel::{
            TexelModel,
            atlas::{TexelAtlas, Texels},
        },
        vertex::Model,
    },
    rig::{clip::Clip, pose::Pose},
    trace::{
        AoBlock, KroonParams, SceneOptions, SurfaceParams, kroon_occlusion, no_progress,
        surface_occlusion, trace_posed,
    },
};

use super::{
    JobError,
    screen_space::{Gtao, ScreenFrame, ScreenSpaceInfo, TexelJudge},
};

/// Side of a still's panels in pixels.
pub const STILL_PANEL: u32 = 360;
/// Side of an animation's panels in pixels.
pub const ANIMATION_PANEL: u32 = 240;
/// Frames per second of an animation (at most [`ANIMATION_MAX_FRAMES`]).
pub const ANIMATION_FPS: f32 = 24.0;
/// Most frames in an animation: a longer clip is sampled more sparsely.
pub const ANIMATION_MAX_FRAMES: usize = 48;
/// Where in a clip a bake's stills are taken, as fractions of its length.
pub const STILL_FRACTIONS: [f32; 3] = [0.15, 0.5, 0.85];
/// Where a texel bake's previews judge each unseen-clip fold per pixel:
/// fractions of the way through the left-out clip's held-out frames (two
/// stills a fold: eight folds add sixteen stills to the previews).
pub const UNSEEN_STILL_FRACTIONS: [f32; 2] = [0.25, 0.75];
/// The ground's half side, in scene radii ([`Camera::scene_radius`]).
const GROUND_RADII: f32 = 3.0;
/// Vertices per side of the ground grid.
pub const GROUND_GRID: usize = 64;
/// Most rays per ground point (the bake's count when lower).
pub const GROUND_SAMPLES: u32 = 128;
/// The baked model a preview shows, and what its panels shade with it.
#[derive(Debug, Clone, Copy)]
pub enum PreviewModel<'a> {
    /// A per-vertex model: the renderer evaluates it on the character
    /// (the ground is ray-traced in every panel).
    Vertex(&'a Model),
    /// A cubemap: the renderer looks it up on the ground at each frame's
    /// phase (the character is ray-traced in every panel); its ground
    /// truth is Eq. 3.1 with these parameters, what the cubemap stores.
    Cubemap(&'a CubemapModel, KroonParams),
    /// Grids: the renderer looks each part's grid up through the part's
    /// pose (the frame's weights, [`grid_weights`]) at the character's
    /// vertices (each on its own part: the owners, `u32::MAX` for none)
    /// and on the ground.
    Grid(&'a GridModel, &'a [u32]),
    /// A texel model: the renderer samples its basis textures
    /// ([`TexelModel::basis`]) per pixel at the atlas's UVs, weighted by
    /// the frame's weights (the ground is ray-traced in every panel); the
    /// atlas's texels are where the truth panel's AO is traced.
    Texel(&'a TexelModel, &'a TexelAtlas),
}

/// Floats per part in a grid frame's weights: `grid_from_world` then
/// `world_from_bind`, each a column-major 4 × 4 matrix.
pub const GRID_POSE_FLOATS: usize = 32;

/// A grid frame's weights: every part's pose ([`GRID_POSE_FLOATS`] each).
pub fn grid_weights(model: &GridModel, palette: &[Mat4]) -> Vec<f32> {
    model
        .poses(palette)
        .iter()
        .flat_map(|p| {
            p.grid_from_world
                .to_cols_array()
                .into_iter()
                .chain(p.world_from_bind.to_cols_array())
        })
        .collect()
}

impl PreviewModel<'_> {
    /// The method.
    pub fn method(&self) -> Method {
        match self {
            Self::Vertex(m) => m.method(),
            Self::Cubemap(m, _) => m.method(),
            Self::Grid(m, _) => m.method(),
            Self::Texel(m, _) => m.method,
        }
    }

    /// What the stills say about the surface the model does not shade.
    fn note(&self) -> &'static str {
        match self {
            Self::Vertex(_) => {
                "ground: ray-traced in every panel (the vertex methods bake the character only)"
            }
            Self::Texel(..) => {
                "character: per pixel from the atlas's textures; ground ray-traced in every panel"
            }
            Self::Cubemap(..) => {
                "character: ray-traced in every panel (the cubemap bakes the occlusion it casts)"
            }
            Self::Grid(..) => "parts and ground shaded by the grids in the model panel",
        }
    }
}

/// What a panel shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Panel {
    /// Shaded with the ray-traced AO.
    Truth,
    /// Shaded with the model's AO, evaluated by the renderer.
    Model,
    /// The model's AO minus the ray-traced AO through [`HeatMap`].
    Error,
    /// Shaded with screen-space AO (GTAO over the frame's G-buffer, with
    /// the scene's [`Gtao`] settings).
    ScreenSpace,
}

/// The camera and the ground of a preview, the same for every frame of a
/// clip so that an animation does not jitter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Where the eye is (world space).
    pub eye: Vec3,
    /// What it looks at: the centre of the clip's bounding box.
    pub target: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    /// Near and far plane distances.
    pub near: f32,
    /// Far plane distance.
    pub far: f32,
    /// Height of the ground plane: the lowest point over the clip.
    pub ground_y: f32,
    /// Half the side of the ground square around the target.
    pub ground_half_extent: f32,
}

impl Camera {
    /// Frames the box `(min, max)` (world space, y up as glTF has it)
    /// from the front right and a little above: the glTF front is +z.
    pub fn framing(min: Vec3, max: Vec3) -> Self {
        let target = 0.5 * (min + max);
        let radius = (0.5 * (max - min).length()).max(1e-3);
        let (azimuth, elevation) = (35f32.to_radians(), 15f32.to_radians());
        let direction = Vec3::new(
            azimuth.sin() * elevation.cos(),
            elevation.sin(),
            azimuth.cos() * elevation.cos(),
        );
        let fov_y = 30f32.to_radians();
        // The nearest eye that keeps every corner of the box inside the
        // (square) view with a 6 % margin: tighter than the bounding
        // sphere for long or flat characters.
        let right = direction.cross(Vec3::Y).normalize_or(Vec3::X) * -1.0;
        let up = right.cross(-direction);
        let tan = (0.5 * fov_y).tan() / 1.06;
        let distance = (0..8)
            .map(|i| {
                let corner = Vec3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                ) - target;
                let z = corner.dot(direction);
                z + corner.dot(right).abs().max(corner.dot(up).abs()) / tan
            })
            .fold(1e-3f32, f32::max);
        Self {
            eye: target + distance * direction,
            target,
            fov_y,
            near: (distance - 4.0 * radius).max(0.02 * distance),
            far: distance + 4.0 * radius,
            ground_y: min.y,
            ground_half_extent: GROUND_RADII * radius,
        }
    }

    /// Clip space (wgpu's, which is Direct3D's: y up, depth 0..1) from
    /// world space.
    pub fn clip_from_world(&self, aspect: f32) -> Mat4 {
        use glam::camera::rh::proj::directx;
        directx::perspective(self.fov_y, aspect, self.near, self.far) * self.view_from_world()
    }

    /// The framed scene's radius (half its bounding box's diagonal): the
    /// ground is [`GROUND_RADII`] of them across each way.
    pub fn scene_radius(&self) -> f32 {
        self.ground_half_extent / GROUND_RADII
    }

    /// View space (x right, y up, looking down −z) from world space.
    pub fn view_from_world(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.eye, self.target, Vec3::Y)
    }
}

/// The ground plane as a grid, denser near the centre where the contact
/// shadows are, so that its ray-traced occlusion is drawn per vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct Ground {
    /// Grid vertices (world space), row-major.
    pub positions: Vec<Vec3>,
    /// Two triangles per cell.
    pub triangles: Vec<[u32; 3]>,
}

impl Camera {
    /// The ground square under the camera's target as a
    /// [`GROUND_GRID`]² grid; spacing grows as |u|^1.8 from the centre.
    pub fn ground(&self) -> Ground {
        let n = GROUND_GRID;
        let e = self.ground_half_extent;
        let coord = |i: usize| {
            let u = 2.0 * i as f32 / (n - 1) as f32 - 1.0;
            u.signum() * u.abs().powf(1.8) * e
        };
        let mut positions = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                positions.push(Vec3::new(
                    self.target.x + coord(i),
                    self.ground_y,
                    self.target.z + coord(j),
                ));
            }
        }
        let mut triangles = Vec::with_capacity(2 * (n - 1) * (n - 1));
        let at = |i: usize, j: usize| (j * n + i) as u32;
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                // Counter-clockwise seen from above (+y).
                triangles.push([at(i, j), at(i, j + 1), at(i + 1, j)]);
                triangles.push([at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)]);
            }
        }
        Ground {
            positions,
            triangles,
        }
    }
}

/// What stays the same over the frames of one render call.
#[derive(Debug, Clone, Copy)]
pub struct RenderScene<'a> {
    /// The character's triangles (counter-clockwise fronts).
    pub triangles: &'a [[u32; 3]],
    /// The model whose AO the renderer evaluates.
    pub model: PreviewModel<'a>,
    /// Camera and ground.
    pub camera: Camera,
    /// The ground grid ([`Camera::ground`]).
    pub ground: &'a Ground,
    /// Panel size in pixels.
    pub size: (u32, u32),
    /// The error colours.
    pub heat_map: HeatMap,
    /// The screen-space baseline's settings.
    pub gtao: Gtao,
}

/// One posed frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderFrame {
    /// World-space positions.
    pub positions: Vec<Vec3>,
    /// World-space unit normals.
    pub normals: Vec<Vec3>,
    /// Ray-traced occlusion per vertex.
    pub truth: Vec<f32>,
    /// The model's weights for this pose ([`Model::weights`]; empty for a
    /// cubemap).
    pub weights: Vec<f32>,
    /// Ray-traced occlusion of each ground vertex by the character: the
    /// truth of a cubemap's ground, drawn in every panel of a vertex
    /// method's (no vertex method bakes it).
    pub ground_ao: Vec<f32>,
    /// The frame's phase of the clip's cycle (a cubemap's lookup).
    pub phase: f32,
    /// Ray-traced occlusion at the texels of the subject's atlas (a texel
    /// model's, or the texel floor's; [`Texels::texels`]' order), empty
    /// without one: a texel model's truth panel samples it as the model
    /// panel samples the model.
    pub texel_truth: Vec<f32>,
}

/// Draws frames: implemented by the worker on wgpu.
pub trait Renderer {
    /// The adapter that draws, such as `llvmpipe (LLVM 15.0.6, 256 bits)
    /// (Gl)`.
    fn adapter(&self) -> String;

    /// Renders every panel of every frame, frame-major: `frames.len() ×
    /// panels.len()` images of `scene.size`.
    fn render(
        &mut self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
        panels: &[Panel],
    ) -> Result<Vec<Image>, String>;

    /// The screen-space baseline of every frame: its G-buffer and GTAO's
    /// occlusion per pixel (`scene.gtao`), read back, with what the GTAO
    /// pass and the model's evaluation each took.
    fn screen_space(
        &mut self,
        scene: &RenderScene<'_>,
        frames: &[RenderFrame],
    ) -> Result<Vec<ScreenFrame>, String>;
}

/// How a preview was made, as listed in `previews.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PreviewInfo {
    /// The output's name, such as `still-0.png`.
    pub name: String,
    /// `still` or `animation`.
    pub kind: String,
    /// The clip, if any (a character without clips is shown at rest).
    pub clip: Option<String>,
    /// Clip times shown, in seconds.
    pub times: Vec<f32>,
    /// Image size.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The adapter that rendered it.
    pub adapter: String,
    /// Milliseconds per rendered panel (GPU evaluation of the model,
    /// drawing and readback), over the render call.
    pub frame_ms: f64,
    /// Seconds spent ray tracing its ground truth (character and ground).
    pub trace_s: f64,
    /// A still's screen-space baseline beside the model, against
    /// per-pixel ray-traced AO.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen_space: Option<ScreenSpaceInfo>,
}

/// A rendered preview.
#[derive(Debug, Clone, PartialEq)]
pub struct Preview {
    /// PNG (an APNG for an animation).
    pub png: Vec<u8>,
    /// How it was made.
    pub info: PreviewInfo,
}

/// The character and model a preview shows, and how its truth is traced.
#[derive(Debug, Clone, Copy)]
pub struct Subject<'a> {
    /// The character.
    pub character: &'a Character,
    /// The baked model.
    pub model: PreviewModel<'a>,
    /// The ray tracing of the ground truth (the bake's held-out seed).
    pub surface: SurfaceParams,
    /// An atlas whose texel floor the stills measure beside the
    /// per-vertex one ([`ScreenSpaceInfo::measure`]).
    pub texel_floor: Option<&'a TexelAtlas>,
    /// A texel model's static average (one value per texel of its atlas),
    /// judged per pixel beside it at every still: an unseen-clip fold's,
    /// the baseline of its gain.
    pub static_texels: Option<&'a [f32]>,
    /// The clip the model never saw, when it is one (an unseen-clip
    /// fold's model): the stills' titles say so.
    pub left_out: Option<&'a str>,
}

impl<'a> Subject<'a> {
    /// `model` on `character`, its truth traced with `surface`: no other
    /// atlas's floor, no static average beside it, trained on every clip
    /// it is shown on (set the fields for those).
    pub fn new(character: &'a Character, model: PreviewModel<'a>, surface: SurfaceParams) -> Self {
        Self {
            character,
            model,
            surface,
            texel_floor: None,
            static_texels: None,
            left_out: None,
        }
    }
    /// The camera for a clip or for the rest pose ([`camera`]).
    pub fn camera(&self, clip: Option<&Clip>) -> Camera {
        camera(self.character, clip)
    }

    /// How this subject's ground truth is traced.
    pub fn tracing(&self) -> TruthTracing {
        TruthTracing {
            surface: self.surface,
            kroon: match self.model {
                PreviewModel::Cubemap(_, kroon) => Some(kroon),
                PreviewModel::Vertex(_) | PreviewModel::Grid(..) | PreviewModel::Texel(..) => None,
            },
        }
    }

    /// The atlas whose texels the truth is traced at: a texel model's, or
    /// the texel floor's.
    pub fn atlas(&self) -> Option<&TexelAtlas> {
        match self.model {
            PreviewModel::Texel(_, atlas) => Some(atlas),
            _ => self.texel_floor,
        }
    }

    /// The posed frames at `times` (the rest pose without a clip): the
    /// character's ray-traced occlusion, the model's weights, and the
    /// occlusion the character casts on `ground`.
    pub fn frames(
        &self,
        clip: Option<&Clip>,
        times: &[f32],
        ground: &Ground,
    ) -> Result<Vec<RenderFrame>, JobError> {
        let poses = frame_poses(self.character, clip, times);
        let texels = self.atlas().map(|a| &a.texels);
        let truth = self
            .tracing()
            .trace(self.character, &poses, ground, texels)?;
        self.frames_with(&poses, times, truth)
    }

    /// The posed frames of `poses` (at clip `times`) with their truth
    /// traced already.
    fn frames_with(
        &self,
        poses: &[Pose],
        times: &[f32],
        truth: FrameTruth,
    ) -> Result<Vec<RenderFrame>, JobError> {
        let skeleton = &self.character.skeleton;
        let texels = self.atlas().map_or(0, |a| a.texels.len());
        if truth.frames() != poses.len()
            || truth.character.vertices != self.character.vertex_count()
            || truth.texels.as_ref().map_or(0, |t| t.vertices) != texels
        {
            return Err(JobError::Invalid(format!(
                "the preview's truth holds {} frames of {} vertices and {} texels, not {} of {} and {texels}",
                truth.frames(),
                truth.character.vertices,
                truth.texels.as_ref().map_or(0, |t| t.vertices),
                poses.len(),
                self.character.vertex_count()
            )));
        }
        Ok(poses
            .iter()
            .enumerate()
            .map(|(i, pose)| {
                let posed = self.character.skin(pose);
                let (weights, phase) = match self.model {
                    PreviewModel::Vertex(model) => (model.weights(skeleton, &pose.locals), 0.0),
                    PreviewModel::Texel(model, _) => {
                        (model.model.weights(skeleton, &pose.locals), 0.0)
                    }
                    PreviewModel::Grid(model, _) => (
                        grid_weights(model, &self.character.joint_matrices(pose)),
                        0.0,
                    ),
                    PreviewModel::Cubemap(model, _) => (Vec::new(), model.layout.phase(times[i])),
                };
                RenderFrame {
                    positions: posed.positions,
                    normals: posed.normals,
                    truth: truth.character.row(i).to_vec(),
                    weights,
                    ground_ao: truth.ground.row(i).to_vec(),
                    phase,
                    texel_truth: truth
                        .texels
                        .as_ref()
                        .map_or_else(Vec::new, |t| t.row(i).to_vec()),
                }
            })
            .collect())
    }

    /// Stills at `times` of `clip` (or one of the rest pose without a
    /// clip: see [`still_times`]), named `still-{i}.png`; their truth is
    /// traced here unless `truth` holds it already.
    pub fn stills(
        &self,
        clip: Option<&Clip>,
        times: &[f32],
        truth: Option<FrameTruth>,
        renderer: &mut dyn Renderer,
    ) -> Result<Vec<Preview>, JobError> {
        let times = still_times(clip, times);
        let prepared = self.prepare(clip, &times, truth)?;
        let panels = [Panel::Truth, Panel::Model, Panel::ScreenSpace, Panel::Error];
        let (images, frame_ms) = self.render(&prepared, STILL_PANEL, &panels, renderer)?;
        let screen = self.screen_space(&prepared, STILL_PANEL, renderer)?;
        let method = self.model.method().name();
        times
            .iter()
            .zip(images.chunks_exact(panels.len()))
            .zip(screen)
            .enumerate()
            .map(|(i, ((&t, row), screen))| {
                let when = match clip {
                    Some(c) => format!("{} at {t:.2} s", c.name),
                    None => "rest pose".to_owned(),
                };
                let baked = match self.left_out {
                    Some(clip) => format!("baked without {clip}: {method}"),
                    None => format!("baked: {method}"),
                };
                let titles = [
                    format!("ray-traced: {when}"),
                    baked,
                    "screen-space: GTAO".to_owned(),
                    "error: baked − ray-traced".to_owned(),
                ];
                let image = compose_row(row, &titles, Some(self.model.note()))?;
                Ok(Preview {
                    info: PreviewInfo {
                        name: format!("still-{i}.png"),
                        kind: "still".into(),
                        clip: clip.map(|c| c.name.clone()),
                        times: vec![t],
                        width: image.width,
                        height: image.height,
                        adapter: renderer.adapter(),
                        frame_ms,
                        trace_s: prepared.trace_s[i],
                        screen_space: Some(screen),
                    },
                    png: encode_image(&image)?,
                })
            })
            .collect()
    }

    /// The camera, the ground and the frames of `times`, traced here
    /// unless `truth` holds them already.
    fn prepare(
        &self,
        clip: Option<&Clip>,
        times: &[f32],
        truth: Option<FrameTruth>,
    ) -> Result<Prepared, JobError> {
        let camera = self.camera(clip);
        let ground = camera.ground();
        let poses = frame_poses(self.character, clip, times);
        let truth = match truth {
            Some(t) => t,
            None => self.tracing().trace(
                self.character,
                &poses,
                &ground,
                self.atlas().map(|a| &a.texels),
            )?,
        };
        let trace_s = truth.seconds.clone();
        let frames = self.frames_with(&poses, times, truth)?;
        Ok(Prepared {
            camera,
            ground,
            frames,
            trace_s,
        })
    }

    /// What a render call of prepared frames in square panels of `side`
    /// pixels draws.
    fn scene<'s>(&'s self, prepared: &'s Prepared, side: u32) -> RenderScene<'s> {
        RenderScene {
            triangles: &self.character.triangles,
            model: self.model,
            camera: prepared.camera,
            ground: &prepared.ground,
            size: (side, side),
            heat_map: HEAT_MAP,
            gtao: Gtao::for_camera(&prepared.camera, self.surface.max_distance),
        }
    }

    /// Renders prepared frames in square panels of `side` pixels; the
    /// images and the milliseconds per panel.
    fn render(
        &self,
        prepared: &Prepared,
        side: u32,
        panels: &[Panel],
        renderer: &mut dyn Renderer,
    ) -> Result<(Vec<Image>, f64), JobError> {
        render(
            renderer,
            &self.scene(prepared, side),
            &prepared.frames,
            panels,
        )
    }

    /// The screen-space baseline of prepared frames in square panels of
    /// `side` pixels, beside the model, against per-pixel ray-traced AO
    /// (see [`ScreenSpaceInfo::measure`]).
    fn screen_space(
        &self,
        prepared: &Prepared,
        side: u32,
        renderer: &mut dyn Renderer,
    ) -> Result<Vec<ScreenSpaceInfo>, JobError> {
        let scene = self.scene(prepared, side);
        let screens = renderer
            .screen_space(&scene, &prepared.frames)
            .map_err(|e| JobError::Failed(format!("the preview renderer failed: {e}")))?;
        let pixels = (side * side) as usize;
        if screens.len() != prepared.frames.len()
            || screens.iter().any(|s| {
                (s.width, s.height) != (side, side)
                    || [s.positions.len(), s.surfaces.len(), s.normals.len()]
                        .into_iter()
                        .chain([s.truth.len(), s.model.len(), s.gtao.len()])
                        .any(|n| n != pixels)
            })
        {
            return Err(JobError::Failed(format!(
                "the renderer returned {} screen-space frames, not {} of {side}×{side}",
                screens.len(),
                prepared.frames.len()
            )));
        }
        let statics: Vec<Vec<f32>> = self
            .static_texels
            .map(<[f32]>::to_vec)
            .into_iter()
            .collect();
        screens
            .iter()
            .zip(&prepared.frames)
            .map(|(screen, frame)| {
                ScreenSpaceInfo::measure(
                    screen,
                    frame,
                    &self.character.triangles,
                    &self.model,
                    &prepared.camera,
                    scene.gtao,
                    &self.surface,
                    self.atlas().map(|atlas| TexelJudge {
                        atlas,
                        models: &statics,
                    }),
                )
                .map_err(|e| JobError::Invalid(e.to_string()))
            })
            .collect()
    }

    /// The whole clip as an APNG, the model beside the ground truth,
    /// named `animation.png`; its truth is traced here unless `truth`
    /// holds it already.
    pub fn animation(
        &self,
        clip: &Clip,
        truth: Option<FrameTruth>,
        renderer: &mut dyn Renderer,
    ) -> Result<Preview, JobError> {
        let fps = animation_fps(clip);
        let times = animation_times(clip);
        let prepared = self.prepare(Some(clip), &times, truth)?;
        let trace_s = prepared.trace_s.iter().sum();
        let panels = [Panel::Truth, Panel::Model];
        let (images, frame_ms) = self.render(&prepared, ANIMATION_PANEL, &panels, renderer)?;
        let method = self.model.method().name();
        let composed = times
            .iter()
            .zip(images.chunks_exact(panels.len()))
            .map(|(&t, pair)| {
                compose_row(
                    pair,
                    &[format!("ray-traced  {t:.2} s"), format!("baked: {method}")],
                    None,
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let png = encode_apng(&composed, 1.0 / fps)?;
        let first = &composed[0];
        Ok(Preview {
            info: PreviewInfo {
                name: "animation.png".into(),
                kind: "animation".into(),
                clip: Some(clip.name.clone()),
                times,
                width: first.width,
                height: first.height,
                adapter: renderer.adapter(),
                frame_ms,
                trace_s,
                screen_space: None,
            },
            png,
        })
    }
}

/// What a render call draws: frames traced under one camera, and the
/// seconds each frame's truth took to trace.
struct Prepared {
    camera: Camera,
    ground: Ground,
    frames: Vec<RenderFrame>,
    trace_s: Vec<f64>,
}

/// The camera for a clip (the box over all its frames at 30 fps, at
/// most 240 of them) or for the rest pose.
pub fn camera(character: &Character, clip: Option<&Clip>) -> Camera {
    let poses: Vec<Pose> = match clip {
        Some(c) => c
            .sample_times(30.0, 240)
            .into_iter()
            .map(|t| Pose::sample(&character.skeleton, c, t))
            .collect(),
        None => vec![Pose::rest(&character.skeleton)],
    };
    let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for pose in &poses {
        for p in character.skin(pose).positions {
            min = min.min(p);
            max = max.max(p);
        }
    }
    if !min.is_finite() {
        (min, max) = (Vec3::ZERO, Vec3::ONE);
    }
    Camera::framing(min, max)
}

/// The frames a bake's previews show.
#[derive(Debug, Clone)]
pub struct PreviewFrames<'c> {
    /// The clip (none: the rest pose).
    pub clip: Option<&'c Clip>,
    /// The stills' times ([`still_times`]).
    pub stills: Vec<f32>,
    /// The animation's times ([`animation_times`]; none without a clip).
    pub animation: Vec<f32>,
}

impl PreviewFrames<'_> {
    /// Every frame: the stills', then the animation's.
    pub fn times(&self) -> Vec<f32> {
        [self.stills.as_slice(), &self.animation].concat()
    }

    /// How many frames there are.
    pub fn len(&self) -> usize {
        self.stills.len() + self.animation.len()
    }

    /// Whether there are none (never for a bake: a still at least).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The times of a bake's stills: `times` of a clip, one at the rest pose
/// without one.
pub fn still_times(clip: Option<&Clip>, times: &[f32]) -> Vec<f32> {
    if clip.is_some() {
        times.to_vec()
    } else {
        vec![0.0]
    }
}

/// The clip times of an animation: evenly spaced, fewer per second for a
/// long clip.
pub fn animation_times(clip: &Clip) -> Vec<f32> {
    let mut times = clip.frame_times(animation_fps(clip));
    times.truncate(ANIMATION_MAX_FRAMES);
    times
}

/// The poses at `times` of `clip`, or the rest pose at each without one.
pub fn frame_poses(character: &Character, clip: Option<&Clip>, times: &[f32]) -> Vec<Pose> {
    let skeleton = &character.skeleton;
    times
        .iter()
        .map(|&t| match clip {
            Some(c) => Pose::sample(skeleton, c, t),
            None => Pose::rest(skeleton),
        })
        .collect()
}

/// How the ground truth of a preview is traced; it needs the bake's
/// parameters, not its model, so it can be traced while the model is
/// still being made (the `preview-truth` jobs).
#[derive(Debug, Clone, Copy)]
pub struct TruthTracing {
    /// The character's rays (the bake's held-out seed); the ground's
    /// surface AO takes at most [`GROUND_SAMPLES`] of them.
    pub surface: SurfaceParams,
    /// A cubemap's: the ground's truth is Eq. 3.1 with these parameters,
    /// what the cubemap stores; else surface AO under the character.
    pub kroon: Option<KroonParams>,
}

/// The ray-traced truth of a run of frames.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTruth {
    /// Occlusion per vertex, a row per frame.
    pub character: AoBlock,
    /// Occlusion of each ground vertex by the character, a row per frame.
    pub ground: AoBlock,
    /// Occlusion at an atlas's texels, a row per frame, when traced.
    pub texels: Option<AoBlock>,
    /// Seconds each frame took to trace.
    pub seconds: Vec<f64>,
}

impl FrameTruth {
    /// Frames held.
    pub fn frames(&self) -> usize {
        self.seconds.len()
    }

    /// Frames `range`, in order.
    pub fn select(&self, range: std::ops::Range<usize>) -> Self {
        Self {
            character: self.character.select(range.clone()),
            ground: self.ground.select(range.clone()),
            texels: self.texels.as_ref().map(|t| t.select(range.clone())),
            seconds: self.seconds[range].to_vec(),
        }
    }
}

impl TruthTracing {
    /// The truth of `character` in `poses` over `ground`, and at
    /// `texels` when given (with the character's rays and seed). Frames
    /// are traced one at a time (each in parallel inside) and do not
    /// depend on each other: a run of frames traced in batches stacks into
    /// the whole, bit for bit.
    pub fn trace(
        &self,
        character: &Character,
        poses: &[Pose],
        ground: &Ground,
        texels: Option<&Texels>,
    ) -> Result<FrameTruth, JobError> {
        let invalid = |e: crate::trace::TraceError| JobError::Invalid(e.to_string());
        let up = vec![Vec3::Y; ground.positions.len()];
        let ground_surface = SurfaceParams {
            samples: self.surface.samples.min(GROUND_SAMPLES),
            ..self.surface
        };
        let options = SceneOptions::default();
        let mut truth = FrameTruth {
            character: AoBlock {
                vertices: character.vertex_count(),
                values: Vec::with_capacity(character.vertex_count() * poses.len()),
            },
            ground: AoBlock {
                vertices: ground.positions.len(),
                values: Vec::with_capacity(ground.positions.len() * poses.len()),
            },
            texels: texels.map(|t| AoBlock {
                vertices: t.len(),
                values: Vec::with_capacity(t.len() * poses.len()),
            }),
            seconds: Vec::with_capacity(poses.len()),
        };
        for pose in poses {
            let started = Instant::now();
            let posed = character.skin(pose);
            let (scene, ao) = trace_posed(character, &posed, &options, &self.surface, &no_progress)
                .map_err(invalid)?;
            // The ground's truth: what the cubemap stores (Eq. 3.1), else
            // surface AO under the character.
            let ground_ao = match &self.kroon {
                Some(kroon) => {
                    kroon_occlusion(&scene, &ground.positions, None, kroon, &no_progress)
                }
                None => surface_occlusion(
                    &scene,
                    &ground.positions,
                    &up,
                    &ground_surface,
                    &no_progress,
                ),
            }
            .map_err(invalid)?;
            if let (Some(texels), Some(block)) = (texels, truth.texels.as_mut()) {
                let (points, normals) =
                    texels.points(&posed.positions, &posed.normals, &character.triangles);
                block.values.extend(
                    surface_occlusion(&scene, &points, &normals, &self.surface, &no_progress)
                        .map_err(invalid)?,
                );
            }
            truth.character.values.extend(ao);
            truth.ground.values.extend(ground_ao);
            truth.seconds.push(started.elapsed().as_secs_f64());
        }
        Ok(truth)
    }
}

fn animation_fps(clip: &Clip) -> f32 {
    if clip.duration > 0.0 {
        ANIMATION_FPS.min((ANIMATION_MAX_FRAMES - 1) as f32 / clip.duration)
    } else {
        ANIMATION_FPS
    }
}

/// Renders and times the call: milliseconds per panel.
fn render(
    renderer: &mut dyn Renderer,
    scene: &RenderScene<'_>,
    frames: &[RenderFrame],
    panels: &[Panel],
) -> Result<(Vec<Image>, f64), JobError> {
    let started = Instant::now();
    let images = renderer
        .render(scene, frames, panels)
        .map_err(|e| JobError::Failed(format!("the preview renderer failed: {e}")))?;
    let ms = 1e3 * started.elapsed().as_secs_f64() / (frames.len() * panels.len()).max(1) as f64;
    let want = frames.len() * panels.len();
    if images.len() != want
        || images.iter().any(|i| {
            (i.width, i.height) != scene.size || i.rgba.len() != 4 * (i.width * i.height) as usize
        })
    {
        return Err(JobError::Failed(format!(
            "the renderer returned {} images, not {want} of {}×{}",
            images.len(),
            scene.size.0,
            scene.size.1
        )));
    }
    Ok((images, ms))
}

/// The font of titles and legends (the report's, DejaVu Sans).
fn font() -> Result<(), JobError> {
    crate::image::register_plot_font().map_err(|e| JobError::Failed(e.to_string()))
}

const TITLE_HEIGHT: u32 = 30;
const LEGEND_HEIGHT: u32 = 46;
const BACKGROUND: u8 = 255;

fn draw_error(e: impl std::fmt::Display) -> JobError {
    JobError::Failed(format!("cannot lay out a preview: {e}"))
}

/// Panels side by side under their titles, and the heat map's legend under
/// the last panel when `legend`.
fn compose_row(
    panels: &[Image],
    titles: &[String],
    legend: Option<&str>,
) -> Result<Image, JobError> {
    font()?;
    let (pw, ph) = (panels[0].width, panels[0].height);
    let width = pw * panels.len() as u32;
    let height = TITLE_HEIGHT + ph + if legend.is_some() { LEGEND_HEIGHT } else { 0 };
    let mut rgb = vec![BACKGROUND; (3 * width * height) as usize];
    for (k, panel) in panels.iter().enumerate() {
        for y in 0..ph {
            for x in 0..pw {
                let from = (4 * (y * pw + x)) as usize;
                let to = (3 * ((TITLE_HEIGHT + y) * width + k as u32 * pw + x)) as usize;
                rgb[to..to + 3].copy_from_slice(&panel.rgba[from..from + 3]);
            }
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let style = TextStyle::from(("sans-serif", 15).into_font()).color(&BLACK);
        for (k, title) in titles.iter().enumerate() {
            root.draw(&Text::new(
                title.clone(),
                (k as i32 * pw as i32 + 8, 8),
                style.clone(),
            ))
            .map_err(draw_error)?;
        }
        if let Some(note) = legend {
            let heat = HEAT_MAP;
            let x0 = (panels.len() as i32 - 1) * pw as i32 + 20;
            let bar = (pw as i32 - 40).max(2);
            let y0 = (TITLE_HEIGHT + ph) as i32 + 6;
            for i in 0..bar {
                let e = heat.range * (2.0 * i as f32 / (bar - 1) as f32 - 1.0);
                let [r, g, b] = heat.color(e).map(crate::image::srgb_byte);
                root.draw(&Rectangle::new(
                    [(x0 + i, y0), (x0 + i + 1, y0 + 14)],
                    RGBColor(r, g, b).filled(),
                ))
                .map_err(draw_error)?;
            }
            let small = TextStyle::from(("sans-serif", 12).into_font()).color(&BLACK);
            root.draw(&Text::new(note, (8, y0 + 20), small.clone()))
                .map_err(draw_error)?;
            for (x, label) in [
                (x0, format!("−{} too bright", heat.range)),
                (x0 + bar / 2 - 4, "0".to_owned()),
                (x0 + bar - 78, format!("+{} too dark", heat.range)),
            ] {
                root.draw(&Text::new(label, (x, y0 + 20), small.clone()))
                    .map_err(draw_error)?;
            }
        }
        root.present().map_err(draw_error)?;
    }
    let rgba = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    Ok(Image {
        width,
        height,
        rgba,
    })
}

/// Output of a `preview` job that could not render (no adapter on the
/// worker's machine): an empty `previews.json` and, in
/// `previews-unavailable.txt`, the reason.
pub fn unavailable(reason: &str) -> super::JobOutput {
    super::JobOutput {
        outputs: vec![
            super::Output {
                name: "previews.json".into(),
                bytes: b"[]".to_vec(),
            },
            super::Output {
                name: UNAVAILABLE.into(),
                bytes: reason.as_bytes().to_vec(),
            },
        ],
        timings: Default::default(),
    }
}

/// The name of the output that says why a bake has no previews.
pub const UNAVAILABLE: &str = "previews-unavailable.txt";

/// The clip a bake's previews show: its first held-out clip, else its
/// first clip.
pub fn preview_clip(clips: &[Clip], test: &[usize]) -> Option<usize> {
    test.first()
        .copied()
        .or(if clips.is_empty() { None } else { Some(0) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_camera_sees_the_whole_box() {
        let (min, max) = (Vec3::new(-0.3, 0.0, -0.2), Vec3::new(0.3, 1.8, 0.2));
        let cam = Camera::framing(min, max);
        let m = cam.clip_from_world(1.0);
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { min.x } else { max.x },
                if i & 2 == 0 { min.y } else { max.y },
                if i & 4 == 0 { min.z } else { max.z },
            );
            let c = m * corner.extend(1.0);
            let ndc = c.truncate() / c.w;
            assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{corner} → {ndc}");
            assert!((0.0..=1.0).contains(&ndc.z), "{corner} depth {}", ndc.z);
        }
        assert_eq!(cam.ground_y, 0.0);
    }

    #[test]
    fn a_still_row_has_its_panels_titles_and_legend() {
        let panel = |v: u8| Image {
            width: 40,
            height: 40,
            rgba: [v, v, v, 255].repeat(1600),
        };
        let titles = ["a".to_owned(), "b".to_owned(), "c".to_owned()];
        let row = compose_row(&[panel(10), panel(20), panel(30)], &titles, Some("note")).unwrap();
        assert_eq!(
            (row.width, row.height),
            (120, 40 + TITLE_HEIGHT + LEGEND_HEIGHT)
        );
        let at = |x: u32, y: u32| row.rgba[(4 * (y * row.width + x)) as usize];
        assert_eq!(at(20, TITLE_HEIGHT + 20), 10);
        assert_eq!(at(60, TITLE_HEIGHT + 20), 20);
        assert_eq!(at(100, TITLE_HEIGHT + 20), 30);
        let encoded = encode_image(&row).unwrap();
        assert!(encoded.starts_with(b"\x89PNG"));
    }
}
