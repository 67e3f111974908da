//! How good a baked cubemap is (DESIGN §6), measured against ground truth
//! it never saw:
//!
//! * **Ground truth**: Eq. 3.1 traced afresh (another seed, more rays) at
//!   random clip times (not only the time samples), at random points in
//!   the spheroid (*space*) and at random points of the ground plane under
//!   the character (*ground*, the receiver a game draws: the plane at the
//!   lowest vertex over the clip, inside the spheroid's footprint). Ground
//!   points the character stands on at that time (a surface within
//!   [`CONTACT`] of the spheroid's size straight above or below) are
//!   hidden under it in any render and are left out of the ground's
//!   figures; so are points in space that the ground truth finds inside
//!   the mesh (occlusion exactly 1, Eq. 3.1's rule), which no render
//!   shows either (Kroon §5.4.1 makes the same point). Both counts are
//!   reported.
//! * **Variants**, each looked up exactly as the run time does: both
//!   encodings, the continuous one without its residual curves (Kroon's
//!   ablation), the uncompressed field (what sampling alone loses: texels,
//!   shells and time samples, interpolated), and a static cubemap (the
//!   field averaged over the cycle: the baseline a pose-independent bake
//!   would give).
//! * **Figures** per variant and receiver: MAE, RMSE, PSNR, too-dark and
//!   too-bright squared error (Kroon's split), bytes; and the encoding's
//!   own error at the sample points it was fitted to.
//! * **Charts** ([`charts_png`]): a texel's (time × distance) field as
//!   input, decoded and error, for the worst, a 90th-percentile and the
//!   median texel (Kroon's Figs. 5.4–5.6).

use glam::Vec3;
use plotters::prelude::*;

use crate::image::srgb_byte;
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{
    face::{FaceField, dequantise},
    geometry::{FACES, texel_direction},
    model::{CubemapLayout, CubemapModel},
    setup::Setup,
};
use crate::{
    asset::metrics::{Errors, FrameError},
    trace::{KroonParams, Scene, SceneOptions, TraceError, kroon_occlusion, no_progress},
};

/// Anything that answers the run-time question: occlusion at a point and
/// a phase of the cycle.
pub trait Lookup: Sync {
    /// Occlusion at `p` at `phase` ∈ [0, 1).
    fn occlusion(&self, p: Vec3, phase: f32) -> f32;

    /// Occlusion at a point `p` of the ground plane.
    fn ground(&self, p: Vec3, phase: f32) -> f32 {
        self.occlusion(p, phase)
    }
}

impl Lookup for CubemapModel {
    fn occlusion(&self, p: Vec3, phase: f32) -> f32 {
        CubemapModel::occlusion(self, p, phase)
    }

    fn ground(&self, p: Vec3, phase: f32) -> f32 {
        self.ground_ao(p, phase)
    }
}

/// The uncompressed fields, looked up like a model (bilinear over texels,
/// linear over shells, linear and cyclic over time samples).
#[derive(Debug, Clone, Copy)]
pub struct RawCubemap<'a> {
    /// Where the fields sit (its encoding is ignored).
    pub layout: CubemapLayout,
    /// The six faces.
    pub faces: &'a [FaceField],
}

impl RawCubemap<'_> {
    /// The raw value of a texel at time `tau` (samples) on shell `k`.
    pub fn texel(&self, face: usize, i: usize, j: usize, tau: f32, k: f32) -> f32 {
        let l = &self.layout;
        let (shells, times) = (l.spheroid.shells, l.times);
        let block = self.faces[face].texel(j * l.resolution + i);
        let at = |k: usize, m: usize| dequantise(block[k * times + m % times]);
        let (k0, m0) = (k.floor() as usize, tau.floor() as usize);
        let (fk, fm) = (k - k0 as f32, tau - m0 as f32);
        let k1 = (k0 + 1).min(shells - 1);
        let shell = |k: usize| at(k, m0) + fm * (at(k, m0 + 1) - at(k, m0));
        shell(k0) + fk * (shell(k1) - shell(k0))
    }
}

impl Lookup for RawCubemap<'_> {
    fn occlusion(&self, p: Vec3, phase: f32) -> f32 {
        self.layout
            .lookup(p, phase, |f, i, j, tau, k| self.texel(f, i, j, tau, k))
    }
}

/// The fields averaged over the cycle: one value per texel and shell.
#[derive(Debug, Clone)]
pub struct StaticCubemap {
    /// Where the fields sit.
    pub layout: CubemapLayout,
    /// `[face][texel][shell]` means.
    pub means: Vec<f32>,
}

impl StaticCubemap {
    /// Averages `faces` over their time samples.
    pub fn of(layout: CubemapLayout, faces: &[FaceField]) -> Self {
        let (shells, times) = (layout.spheroid.shells, layout.times);
        let means = faces
            .iter()
            .flat_map(|f| f.values.chunks_exact(times))
            .map(|curve| curve.iter().map(|&b| dequantise(b)).sum::<f32>() / times as f32)
            .collect::<Vec<f32>>();
        debug_assert_eq!(
            means.len(),
            FACES * layout.resolution * layout.resolution * shells
        );
        Self { layout, means }
    }

    /// Bytes it would take as one byte per texel and shell.
    pub fn bytes(&self) -> usize {
        self.means.len()
    }
}

impl Lookup for StaticCubemap {
    fn occlusion(&self, p: Vec3, phase: f32) -> f32 {
        let l = &self.layout;
        let (res, shells) = (l.resolution, l.spheroid.shells);
        l.lookup(p, phase, |face, i, j, _, k| {
            let base = ((face * res + j) * res + i) * shells;
            let k0 = k.floor() as usize;
            let k1 = (k0 + 1).min(shells - 1);
            let f = k - k0 as f32;
            self.means[base + k0] + f * (self.means[base + k1] - self.means[base + k0])
        })
    }
}

/// Ground truth at random clip times, in space and on the ground.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    /// The clip times.
    pub times: Vec<f32>,
    /// Points per time in space (first) then on the ground.
    pub space: usize,
    /// Points per time on the ground.
    pub ground: usize,
    /// Per time, the points (space, then ground).
    pub points: Vec<Vec<Vec3>>,
    /// Per time, Eq. 3.1 at each point.
    pub truth: Vec<Vec<f32>>,
    /// Per time, whether each point is seen: a point in space not inside
    /// the mesh, a ground point not under the character's contact.
    pub visible: Vec<Vec<bool>>,
    /// The same points of the first time traced again with independent
    /// rays: the ground truth's own noise.
    pub again: Vec<f32>,
    /// Rays traced.
    pub rays: u64,
}

/// Ground points with a surface this close (as a fraction of the
/// spheroid's largest radius) straight above or below are under the
/// character.
pub const CONTACT: f32 = 0.005;

/// Seeds of the evaluation ("cubeeval", "cubenois").
const EVAL_SEED: u64 = 0x6375_6265_6576_616c;
const NOISE_SEED: u64 = 0x6375_6265_6e6f_6973;

impl GroundTruth {
    /// Draws the times and points (seeded by `seed`) and traces them.
    pub fn trace(setup: &Setup<'_>, seed: u64) -> Result<Self, TraceError> {
        let o = &setup.options;
        let s = &setup.spheroid;
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ EVAL_SEED);
        let duration = setup.clip.duration;
        let times: Vec<f32> = (0..o.eval_times)
            .map(|_| rng.random_range(0.0..1.0f32) * duration)
            .collect();
        let ground_y = setup.ground_y();
        let scale = s.radii * s.outer;
        // The spheroid's section at the ground's height.
        let (section_x, section_z) = setup.ground_section();
        let mut points = Vec::with_capacity(times.len());
        for _ in &times {
            let mut ps = Vec::with_capacity(o.eval_points + o.eval_ground);
            while ps.len() < o.eval_points {
                let u = Vec3::new(
                    rng.random_range(-1.0..1.0f32),
                    rng.random_range(-1.0..1.0f32),
                    rng.random_range(-1.0..1.0f32),
                );
                if u.length_squared() <= 1.0 {
                    ps.push(s.centre + scale * u);
                }
            }
            while ps.len() < o.eval_points + o.eval_ground {
                let (x, z) = (
                    rng.random_range(-1.0..1.0f32),
                    rng.random_range(-1.0..1.0f32),
                );
                if x * x + z * z <= 1.0 {
                    ps.push(Vec3::new(
                        s.centre.x + section_x * x,
                        ground_y,
                        s.centre.z + section_z * z,
                    ));
                }
            }
            points.push(ps);
        }
        let kroon = KroonParams {
            samples: o.eval_rays,
            ..o.kroon(s, seed ^ EVAL_SEED)
        };
        let mut truth = Vec::with_capacity(times.len());
        let mut visible = Vec::with_capacity(times.len());
        let reach = CONTACT * s.radii.max_element();
        let mut again = Vec::new();
        for (n, (&t, ps)) in times.iter().zip(&points).enumerate() {
            let positions = setup.positions_at(t);
            let scene = Scene::new(
                &positions,
                &setup.character.triangles,
                &SceneOptions::default(),
            )?;
            let values = kroon_occlusion(&scene, ps, None, &kroon, &no_progress)?;
            visible.push(
                values
                    .iter()
                    .zip(ps)
                    .enumerate()
                    .map(|(i, (&v, &p))| {
                        v < 1.0 && (i < o.eval_points || !scene.surface_near(p, Vec3::Y, reach))
                    })
                    .collect(),
            );
            truth.push(values);
            if n == 0 {
                let noise = KroonParams {
                    seed: seed ^ NOISE_SEED,
                    ..kroon
                };
                again = kroon_occlusion(&scene, ps, None, &noise, &no_progress)?;
            }
        }
        let per_time = (o.eval_points + o.eval_ground) as u64;
        Ok(Self {
            rays: (times.len() as u64 + 1) * per_time * u64::from(o.eval_rays),
            times,
            space: o.eval_points,
            ground: o.eval_ground,
            points,
            truth,
            visible,
            again,
        })
    }

    /// Points left out as hidden, over all times: (in space, on the
    /// ground).
    pub fn hidden(&self) -> (usize, usize) {
        let count = |range: std::ops::Range<usize>| {
            self.visible
                .iter()
                .map(|v| v[range.clone()].iter().filter(|&&s| !s).count())
                .sum()
        };
        (
            count(0..self.space),
            count(self.space..self.space + self.ground),
        )
    }

    /// RMSE of one ground-truth estimate (the difference of two
    /// independent ones over √2): what a perfect cubemap would still score.
    pub fn noise_rmse(&self) -> f64 {
        let Some(first) = self.truth.first() else {
            return 0.0;
        };
        let n = first.len().max(1) as f64;
        let se: f64 = first
            .iter()
            .zip(&self.again)
            .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
            .sum();
        (se / n / 2.0).sqrt()
    }

    /// The errors of `lookup` against the truth, per receiver.
    pub fn errors(&self, lookup: &dyn Lookup, layout: &CubemapLayout) -> (Errors, Errors) {
        let frames: Vec<(FrameError, FrameError)> = self
            .times
            .par_iter()
            .zip(&self.points)
            .zip(&self.truth)
            .zip(&self.visible)
            .map(|(((&t, ps), truth), visible)| {
                let phase = layout.phase(t);
                let seen = |range: std::ops::Range<usize>,
                            look: &dyn Fn(Vec3) -> f32|
                 -> (Vec<f32>, Vec<f32>) {
                    range
                        .filter(|&i| visible[i])
                        .map(|i| (look(ps[i]), truth[i]))
                        .unzip()
                };
                let (space_got, space_want) = seen(0..self.space, &|p| lookup.occlusion(p, phase));
                let (ground_got, ground_want) =
                    seen(self.space..ps.len(), &|p| lookup.ground(p, phase));
                (
                    FrameError::of(&space_got, &space_want),
                    FrameError::of(&ground_got, &ground_want),
                )
            })
            .collect();
        let (space, ground): (Vec<_>, Vec<_>) = frames.into_iter().unzip();
        (Errors::of(&space), Errors::of(&ground))
    }
}

/// One variant's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariantErrors {
    /// Its name, such as `cubemap-continuous`.
    pub name: String,
    /// What it is.
    pub description: String,
    /// Bytes a renderer keeps (texels only).
    pub bytes: usize,
    /// Against the ground truth at random points in the spheroid.
    pub space: Errors,
    /// Against the ground truth on the ground plane.
    pub ground: Errors,
    /// Against the input field at the sample points it encodes (an
    /// encoding's own loss; absent for the references).
    pub fit: Option<FrameError>,
}

/// Texels at which [`fit_error`] and the charts decode (a stride over
/// all of them when there are more).
const FIT_TEXELS: usize = 4096;

/// Every `stride`-th texel of all faces, as (face, texel).
fn sampled_texels(res: usize) -> Vec<(usize, usize)> {
    let all = FACES * res * res;
    let stride = all.div_ceil(FIT_TEXELS).max(1);
    (0..all)
        .step_by(stride)
        .map(|n| (n / (res * res), n % (res * res)))
        .collect()
}

/// The decoded (shell × time) block of a texel, shell-major.
fn decoded_block(model: &CubemapModel, face: usize, texel: usize) -> Vec<f32> {
    let l = &model.layout;
    let (res, shells, times) = (l.resolution, l.spheroid.shells, l.times);
    let (i, j) = (texel % res, texel / res);
    (0..shells * times)
        .map(|n| model.decode_texel(face, i, j, (n % times) as f32, (n / times) as f32))
        .collect()
}

fn input_block(faces: &[FaceField], face: usize, texel: usize) -> Vec<f32> {
    faces[face]
        .texel(texel)
        .iter()
        .map(|&b| dequantise(b))
        .collect()
}

/// A texel as (face, texel in the face) and its error.
pub type TexelError = ((usize, usize), FrameError);

/// Per sampled texel, the encoding's error against the input at the
/// sample points; and the error over all of them.
pub fn fit_error(model: &CubemapModel, faces: &[FaceField]) -> (Vec<TexelError>, FrameError) {
    type Decoded = (TexelError, Vec<f32>, Vec<f32>);
    let per: Vec<Decoded> = sampled_texels(model.layout.resolution)
        .into_par_iter()
        .map(|(face, texel)| {
            let got = decoded_block(model, face, texel);
            let want = input_block(faces, face, texel);
            (((face, texel), FrameError::of(&got, &want)), got, want)
        })
        .collect();
    let got: Vec<f32> = per.iter().flat_map(|p| p.1.iter().copied()).collect();
    let want: Vec<f32> = per.iter().flat_map(|p| p.2.iter().copied()).collect();
    let all = FrameError::of(&got, &want);
    (per.into_iter().map(|(t, _, _)| t).collect(), all)
}

/// A cubemap bake's evaluation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CubemapEvaluation {
    /// The random clip times.
    pub times: Vec<f32>,
    /// Points per time in the spheroid.
    pub space_points: usize,
    /// Points per time on the ground.
    pub ground_points: usize,
    /// Points in space (over all times) left out as inside the mesh.
    pub space_hidden: usize,
    /// Ground points (over all times) left out as under the character.
    pub ground_hidden: usize,
    /// Rays per ground-truth point.
    pub rays_per_point: u32,
    /// RMSE of one ground-truth estimate (see [`GroundTruth::noise_rmse`]).
    pub ground_truth_noise_rmse: f64,
    /// Every variant, the baked one first.
    pub variants: Vec<VariantErrors>,
}

/// The texels the charts show: the worst, the 90th percentile and the
/// median by RMSE of the fit, with their figures.
pub fn chart_texels(
    per_texel: &[((usize, usize), FrameError)],
) -> Vec<(&'static str, (usize, usize), FrameError)> {
    let mut sorted: Vec<&((usize, usize), FrameError)> = per_texel.iter().collect();
    sorted.sort_by(|a, b| b.1.rmse.total_cmp(&a.1.rmse));
    if sorted.is_empty() {
        return Vec::new();
    }
    let n = sorted.len();
    [("worst", 0), ("90th percentile", n / 10), ("median", n / 2)]
        .into_iter()
        .map(|(name, at)| (name, sorted[at.min(n - 1)].0, sorted[at.min(n - 1)].1))
        .collect()
}

/// Squared errors of `model` summed over one texel's chart, as Kroon's
/// Tables 5.1–5.3 give them: (too dark, too bright, total).
pub fn chart_sums(model: &CubemapModel, faces: &[FaceField], texel: (usize, usize)) -> [f64; 3] {
    let e = FrameError::of(
        &decoded_block(model, texel.0, texel.1),
        &input_block(faces, texel.0, texel.1),
    );
    let n = (model.layout.spheroid.shells * model.layout.times) as f64;
    [
        e.too_dark_mse * n,
        e.too_bright_mse * n,
        (e.too_dark_mse + e.too_bright_mse) * n,
    ]
}

/// Kroon's charts (Figs. 5.4–5.6) as one PNG: a row per chosen texel;
/// columns the input, then per encoding its decoded field and its error
/// (decoded − input; red too dark, blue too bright, ±0.1 saturates); time
/// across, distance (shell, innermost at the bottom) up.
pub fn charts_png(
    faces: &[FaceField],
    encodings: &[(&str, &CubemapModel)],
    texels: &[(&str, (usize, usize), FrameError)],
    title: &str,
) -> Result<Vec<u8>, String> {
    crate::image::register_plot_font()?;
    let Some((_, first)) = encodings.first() else {
        return Err("no encoding to chart".into());
    };
    let l = &first.layout;
    let (res, shells, times) = (l.resolution, l.spheroid.shells, l.times);
    // Charts about 384 × 256 pixels, whole pixels per cell: readable at
    // their own size (the dashboard shows them so, in a scrolling frame).
    let (cell_w, cell_h) = (
        384usize.div_ceil(times.max(1)).max(1) as u32,
        256usize.div_ceil(shells.max(1)).max(2) as u32,
    );
    let (chart_w, chart_h) = (cell_w * times as u32, cell_h * shells as u32);
    let (label_h, gap) = (44u32, 14u32);
    // The title, and a line on how to read the charts.
    const HEAD: u32 = 58;
    let columns = 1 + 2 * encodings.len() as u32;
    let width = columns * chart_w + (columns + 1) * gap;
    let row_h = chart_h + label_h + gap;
    let height = HEAD + row_h * texels.len().max(1) as u32;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        root.draw(&Text::new(
            title.to_owned(),
            (gap as i32, 10),
            ("sans-serif", 18),
        ))
        .map_err(e)?;
        root.draw(&Text::new(
            format!(
                "each chart: time across ({times} samples, one cycle), distance up ({shells} shells, the innermost at the bottom); grey: occlusion, white open, black blocked; error: red too dark, blue too bright, ±0.1 saturates"
            ),
            (gap as i32, 34),
            ("sans-serif", 13),
        ))
        .map_err(e)?;
        let heat = crate::image::HEAT_MAP;
        for (row, &(name, (face, texel), err)) in texels.iter().enumerate() {
            let input = input_block(faces, face, texel);
            let y0 = HEAD as i32 + row as i32 * row_h as i32;
            let d = texel_direction(face, texel % res, texel / res, res);
            let caption = format!(
                "{name} texel of {} (face {face}, texel {texel}, direction {:.2} {:.2} {:.2}): RMSE {:.4}",
                encodings[0].0, d.x, d.y, d.z, err.rmse,
            );
            root.draw(&Text::new(caption, (gap as i32, y0), ("sans-serif", 14)))
                .map_err(e)?;
            let mut charts: Vec<(String, Vec<RGBColor>)> =
                vec![("input".into(), input.iter().map(|&v| grey(v)).collect())];
            for (label, model) in encodings {
                let decoded = decoded_block(model, face, texel);
                let [dark, bright, total] = chart_sums(model, faces, (face, texel));
                charts.push((
                    label.to_string(),
                    decoded.iter().map(|&v| grey(v)).collect(),
                ));
                charts.push((
                    format!("error: dark {dark:.2}, bright {bright:.2}, total {total:.2}"),
                    decoded
                        .iter()
                        .zip(&input)
                        .map(|(&got, &want)| {
                            let c = heat.color(got - want);
                            RGBColor(srgb_byte(c[0]), srgb_byte(c[1]), srgb_byte(c[2]))
                        })
                        .collect(),
                ));
            }
            for (col, (label, colors)) in charts.iter().enumerate() {
                let x0 = gap as i32 + col as i32 * (chart_w + gap) as i32;
                root.draw(&Text::new(label.clone(), (x0, y0 + 20), ("sans-serif", 11)))
                    .map_err(e)?;
                let top = y0 + label_h as i32 - 6;
                for k in 0..shells {
                    for m in 0..times {
                        let x = x0 + (m as u32 * cell_w) as i32;
                        let y = top + ((shells - 1 - k) as u32 * cell_h) as i32;
                        root.draw(&Rectangle::new(
                            [(x, y), (x + cell_w as i32, y + cell_h as i32)],
                            colors[k * times + m].filled(),
                        ))
                        .map_err(e)?;
                    }
                }
            }
        }
        root.present().map_err(e)?;
    }
    Ok(crate::image::encode_rgb_png(&rgb, width, height)?)
}

/// Occlusion as a grey: 0 white, 1 black.
fn grey(v: f32) -> RGBColor {
    let g = srgb_byte(1.0 - v.clamp(0.0, 1.0));
    RGBColor(g, g, g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::cubemap::{
        continuous,
        geometry::Spheroid,
        model::{CubemapLayout, Encoding},
    };

    fn layout() -> CubemapLayout {
        CubemapLayout {
            spheroid: Spheroid {
                centre: Vec3::ZERO,
                radii: Vec3::ONE,
                outer: 1.0,
                inner: 0.0,
                shells: 2,
            },
            resolution: 2,
            times: 8,
            encoding: Encoding::Discrete,
            duration: 1.0,
        }
    }

    /// Faces whose texels all hold `value(shell, time)`.
    fn faces(value: impl Fn(usize, usize) -> f32) -> Vec<FaceField> {
        (0..FACES)
            .map(|_| {
                let mut f = FaceField::new(2, 2, 8);
                for m in 0..8 {
                    let slice: Vec<u8> = (0..2 * 4)
                        .map(|p| super::super::face::quantise(value(p / 4, m)))
                        .collect();
                    f.insert(m, &slice);
                }
                f
            })
            .collect()
    }

    #[test]
    fn the_raw_lookup_interpolates_time_cyclically_and_the_static_one_averages() {
        let l = layout();
        let fs = faces(|k, m| if m == 7 { 0.8 } else { 0.2 + 0.1 * k as f32 });
        let raw = RawCubemap {
            layout: l,
            faces: &fs,
        };
        // Shell 0 is at ρ = 0.5; halfway between time samples 7 and 0
        // (phase 7.5 / 8) the value is halfway between 0.8 and 0.2.
        let p = Vec3::new(0.5, 0.0, 0.0);
        let step = 1.0 / 255.0;
        assert!((raw.occlusion(p, 7.5 / 8.0) - 0.5).abs() < step);
        assert!((raw.occlusion(p, 3.0 / 8.0) - 0.2).abs() < step);
        // The static cubemap holds the mean over the cycle.
        let st = StaticCubemap::of(l, &fs);
        assert_eq!(st.bytes(), 6 * 4 * 2);
        let mean = (7.0 * 0.2 + 0.8) / 8.0;
        assert!((st.occlusion(p, 0.1) - mean).abs() < step);
        assert_eq!(st.occlusion(p, 0.1), st.occlusion(p, 0.7));
    }

    #[test]
    fn chart_texels_pick_the_worst_and_the_median_and_the_png_draws() {
        let l = CubemapLayout {
            encoding: Encoding::Continuous,
            ..layout()
        };
        let fs = faces(|k, m| 0.1 + 0.05 * k as f32 + 0.02 * m as f32);
        let model = crate::method::cubemap::model::encode(
            l,
            &fs,
            continuous::Encoding {
                bright_weight: 0.6,
                residuals: true,
            },
        )
        .unwrap();
        let (per, all) = fit_error(&model, &fs);
        assert_eq!(per.len(), 24);
        // A cyclic sawtooth: the cosine basis smooths its jump.
        assert!(all.rmse < 0.05, "{all:?}");
        let chosen = chart_texels(&per);
        assert_eq!(chosen[0].0, "worst");
        assert!(chosen[0].2.rmse >= chosen[2].2.rmse);
        let png = charts_png(&fs, &[("continuous", &model)], &chosen, "test").unwrap();
        let [dark, bright, total] = chart_sums(&model, &fs, chosen[0].1);
        assert!((dark + bright - total).abs() < 1e-9 && total >= 0.0);
        assert_eq!(&png[1..4], b"PNG");
    }
}
