//! The screen-space baseline: what engines compute at run time when they
//! have no bake. GTAO (Jimenez et al. 2016) runs on the preview renderer's
//! G-buffer (`shaders/wgsl/gtao.wgsl`), becomes a fourth panel of every
//! still, and is judged per pixel beside the baked model: at a grid of the
//! still's pixels, the occlusion is ray-traced at the very point and
//! normal the pixel shows (Eq. 1, the bake's rays and distance limit), and
//! GTAO, the model and the per-vertex truth (interpolated, the floor of
//! anything stored per vertex) are compared with it.
//!
//! Screen-space AO sees only what is on screen, only within its radius,
//! and only the nearest surface per pixel; the bake sees everything. The
//! comparison shows what that costs, and what each costs to run.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::preview::{Camera, PreviewModel, RenderFrame};
use crate::{
    asset::metrics::FrameError,
    method::texel::atlas::{TexelAtlas, barycentric},
    trace::{Scene, SceneOptions, SurfaceParams, TraceError, no_progress, surface_occlusion},
};

/// GTAO's settings: a high-quality reference setting (many slices and
/// steps, no noise, so no denoiser and no temporal accumulation), not an
/// engine's cheapest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Gtao {
    /// Screen directions per pixel, each a slice through both sides.
    pub slices: u32,
    /// Samples per side of a slice.
    pub steps: u32,
    /// Occluders farther than this from the pixel count not (world units).
    pub radius: f32,
    /// The fraction of the radius over which an occluder fades out.
    pub falloff: f32,
}

impl Gtao {
    /// Slices per pixel.
    pub const SLICES: u32 = 8;
    /// Steps per side of a slice.
    pub const STEPS: u32 = 12;
    /// The radius as a fraction of the framed scene's radius (half the
    /// clip's bounding-box diagonal): about half a metre on a person. Of
    /// 1/4, 1/2, 1 and 2 it gave GTAO the least error against per-pixel
    /// ray-traced AO on Fox's and the Kenney character's walks, on the
    /// character and on the ground alike.
    pub const RADIUS_FRACTION: f32 = 0.5;
    /// XeGTAO's default falloff range.
    pub const FALLOFF: f32 = 0.615;

    /// The settings for a preview's camera: the radius
    /// [`Gtao::RADIUS_FRACTION`] of the scene's, and no farther than the
    /// bake's distance limit.
    pub fn for_camera(camera: &Camera, max_distance: f32) -> Self {
        let scene_radius = camera.scene_radius();
        Self {
            slices: Self::SLICES,
            steps: Self::STEPS,
            radius: (Self::RADIUS_FRACTION * scene_radius).min(max_distance),
            falloff: Self::FALLOFF,
        }
    }

    /// G-buffer texels read per pixel.
    pub fn fetches_per_pixel(&self) -> u32 {
        2 * self.slices * self.steps
    }
}

/// What a pixel of the G-buffer shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    /// The background.
    None,
    /// The character.
    Character,
    /// The ground.
    Ground,
}

impl Surface {
    /// The G-buffer's code (`preview.wgsl`'s `fs_gbuffer`): 0 none, 1
    /// character, 2 ground.
    pub fn from_code(code: u32) -> Self {
        match code {
            1 => Self::Character,
            2 => Self::Ground,
            _ => Self::None,
        }
    }
}

/// One frame's screen-space buffers, row-major, as the renderer reads
/// them back from the G-buffer pass and the GTAO pass.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenFrame {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// World position per pixel.
    pub positions: Vec<Vec3>,
    /// What each pixel shows.
    pub surfaces: Vec<Surface>,
    /// The interpolated shading normal (not unit length).
    pub normals: Vec<Vec3>,
    /// The per-vertex ray-traced AO, interpolated.
    pub truth: Vec<f32>,
    /// The model's AO, interpolated (the truth where the model shades
    /// nothing: a vertex method's ground, a cubemap's character).
    pub model: Vec<f32>,
    /// GTAO's occlusion (negative where no surface is).
    pub gtao: Vec<f32>,
    /// Milliseconds of the GTAO pass alone (dispatch to completion).
    pub gtao_ms: f64,
    /// Milliseconds of the model's evaluation alone (a vertex method's
    /// compute pass, a cubemap's or the grids' lookups), or 0 where the
    /// renderer has none to time.
    pub model_ms: f64,
}

/// Errors against per-pixel ray-traced AO on one surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceErrors {
    /// Pixels compared.
    pub pixels: usize,
    /// GTAO.
    pub gtao: FrameError,
    /// The baked model, where it shades this surface.
    pub model: Option<FrameError>,
    /// Where it is not judged here, why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_not_judged: Option<String>,
    /// The per-vertex ray-traced AO interpolated across triangles: the
    /// best any per-vertex storage can do at these pixels.
    pub per_vertex_truth: FrameError,
    /// The ray-traced AO at the texel centres of an atlas, filtered as a
    /// GPU's linear sampler filters the dilated texture: the best any
    /// texture of that atlas can do at these pixels (the character only,
    /// when the preview is given an atlas).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texel_truth: Option<FrameError>,
    /// The texel models the still was given ([`TexelJudge::models`]),
    /// looked up as the texel floor is.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub texel_models: Vec<FrameError>,
}

/// What a still judges in texture space: an atlas, whose texel floor is
/// traced at the frame, and the per-texel values of texel models at the
/// frame's pose, each looked up per pixel as an engine's linear sampler
/// would read its dilated texture.
#[derive(Debug, Clone, Copy)]
pub struct TexelJudge<'a> {
    /// The atlas.
    pub atlas: &'a TexelAtlas,
    /// Per model, one value per texel of the atlas.
    pub models: &'a [Vec<f32>],
}

/// The atlas a still's texel floor was measured with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AtlasInfo {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Charts.
    pub charts: u32,
    /// Texels that show the surface (inside and on chart borders).
    pub texels: usize,
    /// The share of the atlas's texels whose centre lies on the surface.
    pub utilisation: f64,
    /// Seconds spent tracing the texels here: 0 when the frame's truth
    /// held them already, as a preview's frames do (they are traced with
    /// the frame, and counted in its `trace_s`).
    pub trace_s: f64,
}

/// The screen-space baseline beside the model at one still, as
/// `previews.json` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenSpaceInfo {
    /// GTAO's settings.
    pub gtao: Gtao,
    /// Every `stride`-th pixel in x and y is compared.
    pub stride: u32,
    /// Rays per compared pixel.
    pub rays: u32,
    /// On the character.
    pub character: Option<SurfaceErrors>,
    /// On the ground within one scene radius of the target (the contact
    /// region: farther out both are near zero).
    pub ground: Option<SurfaceErrors>,
    /// Milliseconds of the GTAO pass per frame on the preview's adapter.
    pub gtao_ms: f64,
    /// Milliseconds of the model's run-time evaluation per frame on the
    /// same adapter.
    pub model_ms: f64,
    /// G-buffer texels GTAO reads per pixel.
    pub fetches_per_pixel: u32,
    /// Pixels GTAO runs on per frame (the whole panel).
    pub pixels: u64,
    /// The atlas of the texel floor, when one was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub atlas: Option<AtlasInfo>,
}

/// Every `STRIDE`-th pixel in x and y is ray-traced.
pub const STRIDE: u32 = 3;

impl ScreenSpaceInfo {
    /// Measures one frame: the per-pixel truth traced on `frame`'s posed
    /// character (and its ground plane) at the pixels `screen` shows, with
    /// the bake's rays and distance limit (`surface`). With `texels`, the
    /// frame's AO is also traced at an atlas's texels (the texel floor),
    /// and it and the texel models are looked up per character pixel
    /// where a ray from the eye meets the posed mesh.
    #[allow(clippy::too_many_arguments)]
    pub fn measure(
        screen: &ScreenFrame,
        frame: &RenderFrame,
        triangles: &[[u32; 3]],
        model: &PreviewModel<'_>,
        camera: &Camera,
        gtao: Gtao,
        surface: &SurfaceParams,
        texels: Option<TexelJudge<'_>>,
    ) -> Result<Self, TraceError> {
        let atlas = texels.map(|t| t.atlas);
        let models: Vec<Vec<f32>> = texels.map_or_else(Vec::new, |t| {
            t.models.iter().map(|m| t.atlas.texels.image(m)).collect()
        });
        let scene = Scene::new(&frame.positions, triangles, &SceneOptions::default())?;
        let started = std::time::Instant::now();
        let texel_image = atlas
            .map(|a| {
                // The frame's own texel truth when it was traced with it
                // (a texel model's preview), else traced here.
                if frame.texel_truth.len() == a.texels.len() {
                    return Ok(a.texels.image(&frame.texel_truth));
                }
                if !frame.texel_truth.is_empty() {
                    return Err(TraceError::Invalid(format!(
                        "the frame's truth holds {} texels, the atlas {}",
                        frame.texel_truth.len(),
                        a.texels.len()
                    )));
                }
                let (points, normals) =
                    a.texels.points(&frame.positions, &frame.normals, triangles);
                let values = surface_occlusion(&scene, &points, &normals, surface, &no_progress)?;
                Ok::<_, TraceError>(a.texels.image(&values))
            })
            .transpose()?;
        let texel_trace_s = started.elapsed().as_secs_f64();
        let contact = camera.scene_radius();
        let target = camera.target;
        let mut character = Vec::new();
        let mut ground = Vec::new();
        for y in (0..screen.height).step_by(STRIDE as usize) {
            for x in (0..screen.width).step_by(STRIDE as usize) {
                let i = (y * screen.width + x) as usize;
                let p = screen.positions[i];
                match screen.surfaces[i] {
                    Surface::Character => character.push(i),
                    Surface::Ground if (p.x - target.x).hypot(p.z - target.z) <= contact => {
                        ground.push(i)
                    }
                    _ => {}
                }
            }
        }
        // Where the model is judged against per-pixel AO, and else why not.
        let cubemap = "a cubemap stores Kroon's Eq. 3.1 (occlusion cast into space), not this AO: the bake's report judges it against its own truth";
        let (model_on_character, model_on_ground) = match model {
            PreviewModel::Vertex(_) => (
                None,
                Some("a vertex asset shades the character, not the ground"),
            ),
            PreviewModel::Texel(..) => (
                None,
                Some("a texel asset shades the character, not the ground"),
            ),
            PreviewModel::Cubemap(..) => (Some(cubemap), Some(cubemap)),
            PreviewModel::Grid(..) => (None, None),
        };
        // The textures at a pixel (the floor's, then the models'): each
        // looked up at the point of the posed mesh the eye sees through it.
        let texel_lookups = |pixels: &[usize]| -> Option<Vec<Vec<f32>>> {
            let (a, floor) = atlas.zip(texel_image.as_ref())?;
            let images: Vec<&Vec<f32>> = std::iter::once(floor).chain(&models).collect();
            let mut out = vec![Vec::with_capacity(pixels.len()); images.len()];
            for &i in pixels {
                let dir = screen.positions[i] - camera.eye;
                let hit = scene.first_hit(camera.eye, dir).map(|(t, distance)| {
                    let p = camera.eye + dir.normalize() * distance;
                    let corners = triangles[t].map(|v| frame.positions[v as usize]);
                    (t, barycentric(p, corners))
                });
                for (o, image) in out.iter_mut().zip(&images) {
                    o.push(match hit {
                        Some((t, bary)) => a.sample(image, t, bary),
                        // A pixel the eye's ray misses (a silhouette's
                        // rounding): the interpolated per-vertex truth.
                        None => screen.truth[i].max(0.0),
                    });
                }
            }
            Some(out)
        };
        let judge = |pixels: &[usize],
                     up: Option<Vec3>,
                     not_judged: Option<&str>,
                     texels: Option<Vec<Vec<f32>>>| {
            let with_model = not_judged.is_none();
            if pixels.is_empty() {
                return Ok(None);
            }
            let points: Vec<Vec3> = pixels.iter().map(|&i| screen.positions[i]).collect();
            let normals: Vec<Vec3> = pixels
                .iter()
                .map(|&i| {
                    // The authored normal, as the per-vertex truth uses
                    // it (GTAO turns it towards the eye, as it must).
                    up.unwrap_or_else(|| screen.normals[i].normalize_or(Vec3::Y))
                })
                .collect();
            let truth = surface_occlusion(&scene, &points, &normals, surface, &no_progress)?;
            let pick = |v: &[f32]| -> Vec<f32> { pixels.iter().map(|&i| v[i].max(0.0)).collect() };
            Ok(Some(SurfaceErrors {
                pixels: pixels.len(),
                gtao: FrameError::of(&pick(&screen.gtao), &truth),
                model: with_model.then(|| FrameError::of(&pick(&screen.model), &truth)),
                model_not_judged: not_judged.map(str::to_owned),
                per_vertex_truth: FrameError::of(&pick(&screen.truth), &truth),
                texel_truth: texels.as_ref().map(|t| FrameError::of(&t[0], &truth)),
                texel_models: texels.map_or_else(Vec::new, |t| {
                    t[1..].iter().map(|m| FrameError::of(m, &truth)).collect()
                }),
            }))
        };
        Ok(Self {
            gtao,
            stride: STRIDE,
            rays: surface.samples,
            character: judge(
                &character,
                None,
                model_on_character,
                texel_lookups(&character),
            )?,
            ground: judge(&ground, Some(Vec3::Y), model_on_ground, None)?,
            gtao_ms: screen.gtao_ms,
            model_ms: screen.model_ms,
            fetches_per_pixel: gtao.fetches_per_pixel(),
            pixels: u64::from(screen.width) * u64::from(screen.height),
            atlas: atlas.map(|a| AtlasInfo {
                width: a.atlas.width,
                height: a.atlas.height,
                charts: a.atlas.charts,
                texels: a.texels.len(),
                utilisation: a.texels.utilisation(),
                trace_s: texel_trace_s,
            }),
        })
    }
}

impl ScreenSpaceInfo {
    /// The comparison as a person reads it: per surface, each one's RMSE
    /// against per-pixel ray-traced AO, then what each costs per frame.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        for (name, errors) in [("character", &self.character), ("ground", &self.ground)] {
            let Some(e) = errors else { continue };
            let model = match (e.model, &e.model_not_judged) {
                (Some(m), _) => format!("{:.4} ({:.1} dB)", m.rmse, m.psnr_db),
                (None, Some(why)) => format!("not judged ({why})"),
                (None, None) => "—".to_owned(),
            };
            let texel = match (e.texel_truth, &self.atlas) {
                (Some(t), Some(a)) => format!(
                    ", texel truth {:.4} ({}×{} atlas, {} texels)",
                    t.rmse, a.width, a.height, a.texels
                ),
                _ => String::new(),
            };
            out.push_str(&format!(
                "  {name} ({} pixels): RMSE against per-pixel ray-traced AO: baked model {model}, GTAO {:.4} ({:.1} dB), per-vertex truth {:.4}{texel}\n",
                e.pixels, e.gtao.rmse, e.gtao.psnr_db, e.per_vertex_truth.rmse
            ));
        }
        out.push_str(&format!(
            "  per frame: GTAO {:.2} ms ({} pixels × {} texel reads, radius {:.3}), the model's evaluation {:.2} ms\n",
            self.gtao_ms, self.pixels, self.fetches_per_pixel, self.gtao.radius, self.model_ms
        ));
        out
    }
}

/// The name of a preview job's per-pixel summary ([`PixelSummary`]).
pub const PIXELS: &str = "pixels.json";

/// Per-pixel errors on the character against ray-traced AO, pooled over
/// the stills of one clip (RMSEs over all their compared pixels).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PixelErrors {
    /// The clip.
    pub clip: String,
    /// Whether the model judged here was trained on the clip (an
    /// unseen-clip fold's model never saw it).
    pub trained: bool,
    /// Stills pooled.
    pub stills: usize,
    /// Pixels compared.
    pub pixels: usize,
    /// The baked model.
    pub model: f64,
    /// The static average judged beside it (an unseen fold's: the mean of
    /// the other clips' frames), where one was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub static_average: Option<f64>,
    /// The model's PSNR over the static average's (dB), where one was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_db: Option<f64>,
    /// GTAO.
    pub gtao: f64,
    /// The per-vertex floor: the exact AO at the vertices, interpolated.
    pub per_vertex_floor: f64,
    /// The texel floor: the exact AO at the atlas's texels, filtered as
    /// the shader filters (texel models only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texel_floor: Option<f64>,
}

/// A bake's models judged per pixel on its previews' stills, per clip:
/// the bake's own model on the stills of its preview clip, and (texel
/// bakes) each unseen-clip fold's model on stills of the clip it left out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PixelSummary {
    /// The bake's model on its previews' stills.
    pub stills: Vec<PixelErrors>,
    /// Each unseen-clip fold's model on the clip it left out.
    pub unseen: Vec<PixelErrors>,
    /// Mean over the unseen clips of the gain over the static average
    /// (dB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unseen_mean_gain_db: Option<f64>,
    /// The smallest gain of an unseen clip (dB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unseen_worst_gain_db: Option<f64>,
    /// The largest ratio of a model's RMSE to GTAO's over every entry
    /// (below 1: the model beats screen-space AO everywhere judged).
    pub worst_gtao_ratio: f64,
}

impl PixelSummary {
    /// The summary of a preview job's stills (`infos`): those of kind
    /// `still` and `unseen` whose model was judged on the character,
    /// pooled per kind and clip; `trained` says whether the bake's model
    /// saw a clip. `None` when no still was judged.
    pub fn of<'i>(
        infos: impl IntoIterator<Item = &'i super::PreviewInfo>,
        trained: impl Fn(&str) -> bool,
    ) -> Option<Self> {
        struct Pool {
            clip: String,
            trained: bool,
            stills: usize,
            pixels: usize,
            // Sums of pixels × MSE.
            model: f64,
            statics: Option<f64>,
            gtao: f64,
            vertex: f64,
            texel: Option<f64>,
        }
        let mut pools: [Vec<Pool>; 2] = [Vec::new(), Vec::new()];
        for info in infos {
            let unseen = match info.kind.as_str() {
                "still" => false,
                super::texel::UNSEEN_KIND => true,
                _ => continue,
            };
            let (Some(clip), Some(s)) = (&info.clip, &info.screen_space) else {
                continue;
            };
            let Some(e) = &s.character else { continue };
            let Some(model) = e.model else { continue };
            let pool = &mut pools[usize::from(unseen)];
            if pool.last().is_none_or(|p| &p.clip != clip) {
                pool.push(Pool {
                    clip: clip.clone(),
                    trained: !unseen && trained(clip),
                    stills: 0,
                    pixels: 0,
                    model: 0.0,
                    statics: Some(0.0),
                    gtao: 0.0,
                    vertex: 0.0,
                    texel: Some(0.0),
                });
            }
            let p = pool.last_mut().expect("just pushed");
            let n = e.pixels as f64;
            let sq = |f: &FrameError| n * f.rmse * f.rmse;
            p.stills += 1;
            p.pixels += e.pixels;
            p.model += sq(&model);
            p.gtao += sq(&e.gtao);
            p.vertex += sq(&e.per_vertex_truth);
            // Judged at every still of the clip, or not reported.
            p.statics = p
                .statics
                .zip(e.texel_models.first())
                .map(|(a, f)| a + sq(f));
            p.texel = p.texel.zip(e.texel_truth.as_ref()).map(|(a, f)| a + sq(f));
        }
        let [stills, unseen] = pools.map(|pool| {
            pool.into_iter()
                .map(|p| {
                    let rmse = |sum: f64| (sum / p.pixels.max(1) as f64).sqrt();
                    let model = rmse(p.model);
                    let static_average = p.statics.map(rmse);
                    PixelErrors {
                        clip: p.clip,
                        trained: p.trained,
                        stills: p.stills,
                        pixels: p.pixels,
                        model,
                        static_average,
                        gain_db: static_average.map(|s| 20.0 * (s / model).log10()),
                        gtao: rmse(p.gtao),
                        per_vertex_floor: rmse(p.vertex),
                        texel_floor: p.texel.map(rmse),
                    }
                })
                .collect::<Vec<_>>()
        });
        if stills.is_empty() && unseen.is_empty() {
            return None;
        }
        let gains: Vec<f64> = unseen.iter().filter_map(|e| e.gain_db).collect();
        let worst_gtao_ratio = stills
            .iter()
            .chain(&unseen)
            .map(|e| e.model / e.gtao)
            .fold(0.0, f64::max);
        Some(Self {
            unseen_mean_gain_db: (!gains.is_empty())
                .then(|| gains.iter().sum::<f64>() / gains.len() as f64),
            unseen_worst_gain_db: gains.iter().copied().reduce(f64::min),
            worst_gtao_ratio,
            stills,
            unseen,
        })
    }

    /// The summary as a person reads it: a table per clip, then the
    /// unseen clips' gains.
    pub fn lines(&self) -> String {
        let opt = |x: Option<f64>| x.map_or("—".to_owned(), |x| format!("{x:.4}"));
        let mut out = String::from(
            "per pixel on the character, RMSE against ray-traced AO:\n| clip | model | stills | pixels | model | static average | gain | texel floor | per-vertex floor | GTAO | model / GTAO |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for (e, whose) in self
            .stills
            .iter()
            .map(|e| {
                (
                    e,
                    if e.trained {
                        "the bake's (trained on it)"
                    } else {
                        "the bake's (held out of training)"
                    },
                )
            })
            .chain(self.unseen.iter().map(|e| (e, "refitted without it")))
        {
            out.push_str(&format!(
                "| {} | {whose} | {} | {} | {:.4} | {} | {} | {} | {:.4} | {:.4} | {:.2} |\n",
                e.clip,
                e.stills,
                e.pixels,
                e.model,
                opt(e.static_average),
                e.gain_db.map_or("—".to_owned(), |g| format!("{g:+.2} dB")),
                opt(e.texel_floor),
                e.per_vertex_floor,
                e.gtao,
                e.model / e.gtao,
            ));
        }
        if let (Some(mean), Some(worst)) = (self.unseen_mean_gain_db, self.unseen_worst_gain_db) {
            out.push_str(&format!(
                "unseen clips per pixel: {mean:+.2} dB over the static average on average, worst clip {worst:+.2} dB; "
            ));
        }
        out.push_str(&format!(
            "worst model / GTAO {:.2}\n",
            self.worst_gtao_ratio
        ));
        out
    }
}
