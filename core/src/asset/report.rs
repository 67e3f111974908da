//! The report every bake carries (DESIGN §6): a JSON document and a PNG.
//! A per-vertex bake's [`Report`] plots PSNR per frame over each test clip
//! for the model and the static-average baseline, as Kontkanen & Aila plot
//! it (Fig. 3); a cubemap bake's [`CubemapReport`] gives every encoding's
//! errors in space and on the ground and Kroon's time × distance charts.
//! [`BakeReport`] is either, told apart by the method.

use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    asset::metrics::psnr,
    bake::{BakeParams, Evaluation, FitStats},
    method::{
        Family, Method,
        cubemap::{evaluate::CubemapEvaluation, model::CubemapLayout},
    },
    trace::AoBlock,
};

/// Wall-clock seconds of each stage (summed over jobs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Timings {
    /// Ray tracing the reference poses (a cubemap: its six faces).
    pub reference_trace_s: f64,
    /// Fitting the model and the baseline (a cubemap: encoding it).
    pub fit_s: f64,
    /// Ray tracing the held-out poses (a cubemap: the evaluation's ground
    /// truth).
    pub test_trace_s: f64,
    /// Evaluating the model on them.
    pub evaluate_s: f64,
    /// The unseen-clip folds' refits and judgements (summed over the
    /// folds, which run side by side as jobs of their own).
    #[serde(default)]
    pub unseen_s: f64,
}

/// Sizes of the model and the baseline.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Sizes {
    /// The whole asset file.
    pub asset_bytes: usize,
    /// The model's numbers alone (coefficients, maps, cluster data).
    pub model_bytes: usize,
    /// The baseline's numbers (one f16 per vertex).
    pub baseline_bytes: usize,
}

/// The character a bake ran on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CharacterInfo {
    /// Upload digest.
    pub digest: String,
    /// Vertices.
    pub vertices: usize,
    /// Triangles.
    pub triangles: usize,
    /// Every clip's name.
    pub clips: Vec<String>,
    /// Clips the model was fitted on.
    pub train_clips: Vec<String>,
    /// Clips whose frames were held out.
    pub test_clips: Vec<String>,
    /// Joint-angle parameters (Kontkanen & Aila).
    pub joint_angle_parameters: usize,
    /// Handle coordinates (Kirk & Arikan).
    pub handle_coordinates: usize,
}

/// A bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character.
    pub character: CharacterInfo,
    /// Rays traced for reference and held-out poses.
    pub rays: u64,
    /// Stage times.
    pub timings: Timings,
    /// The fit's own figures.
    pub fit: FitStats,
    /// Sizes.
    pub sizes: Sizes,
    /// Held-out errors against the baseline.
    pub evaluation: Evaluation,
    /// How noisy the ground truth itself is.
    pub ground_truth_noise: NoiseEstimate,
}

/// A cubemap bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CubemapReport {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character (its train and test clips are the baked clip).
    pub character: CharacterInfo,
    /// The baked clip.
    pub clip: String,
    /// Where the cubemaps sit.
    pub layout: CubemapLayout,
    /// Rays traced: the faces' sample points and the ground truth.
    pub rays: u64,
    /// Stage times.
    pub timings: Timings,
    /// Sizes: the asset, its texels, and the static baseline (a byte per
    /// texel and shell).
    pub sizes: Sizes,
    /// Every encoding and reference against the ground truth.
    pub evaluation: CubemapEvaluation,
    /// The texels the charts (`plot.png`) show, with each encoding's
    /// summed squared errors there.
    pub charts: Vec<ChartTexel>,
}

/// A grid bake's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridReport {
    /// The method.
    pub method: Method,
    /// The bake key.
    pub bake_key: String,
    /// The parameters.
    pub params: BakeParams,
    /// The character.
    pub character: CharacterInfo,
    /// Every part's grid.
    pub parts: Vec<PartReport>,
    /// Rays traced: the cells and the ground truth.
    pub rays: u64,
    /// Stage times (`reference_trace_s`: the slabs, summed).
    pub timings: Timings,
    /// Sizes: the asset, its cells (and `T_clip`), and the static average
    /// (one f16 per vertex).
    pub sizes: Sizes,
    /// Every variant against the ground truth.
    pub evaluation: crate::method::grid::evaluate::GridEvaluation,
}

/// One part's grid in a report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartReport {
    /// The part (its node's name).
    pub name: String,
    /// Its node.
    pub node: usize,
    /// Vertices it carries.
    pub vertices: usize,
    /// Its triangles.
    pub triangles: usize,
    /// Cells per grid edge.
    pub resolution: usize,
    /// The grid's half extent per axis (Eq. 4), bind space.
    pub half_extent: [f32; 3],
    /// V_M, the boundary maximum the cells were rescaled by.
    pub boundary_max: f32,
    /// Cells inside the part, filled from their neighbours.
    pub inside_cells: usize,
    /// Bytes its cells take with cones (RGBA) and without (one byte).
    pub bytes: [usize; 2],
    /// Seconds its slabs traced (summed over slab jobs).
    pub bake_s: f64,
}

/// A texel of the charts and each encoding's squared errors summed over
/// its (time × distance) chart against the input, as Kroon's Tables
/// 5.1–5.3 give them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChartTexel {
    /// Why it was chosen: `worst`, `90th percentile` or `median`.
    pub name: String,
    /// Its face.
    pub face: usize,
    /// Its texel in the face (`j · resolution + i`).
    pub texel: usize,
    /// Per encoding: (too dark, too bright, total).
    pub sums: Vec<(String, [f64; 3])>,
}

/// Either kind of report, told apart by its method's family.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum BakeReport {
    /// A per-vertex bake's.
    Vertex(Box<Report>),
    /// A cubemap bake's.
    Cubemap(Box<CubemapReport>),
    /// A grid bake's.
    Grid(Box<GridReport>),
}

impl<'de> Deserialize<'de> for BakeReport {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error as _;
        let value = serde_json::Value::deserialize(d)?;
        let method: Method = serde_json::from_value(value["method"].clone())
            .map_err(|e| D::Error::custom(format!("report.method: {e}")))?;
        match method.family() {
            Family::Vertex => serde_json::from_value(value).map(Self::Vertex),
            Family::Cubemap => serde_json::from_value(value).map(Self::Cubemap),
            Family::Grid => serde_json::from_value(value).map(Self::Grid),
        }
        .map_err(D::Error::custom)
    }
}

impl BakeReport {
    /// The per-vertex report, if it is one.
    pub fn vertex(&self) -> Option<&Report> {
        match self {
            Self::Vertex(r) => Some(r),
            Self::Cubemap(_) | Self::Grid(_) => None,
        }
    }
}

/// The Monte Carlo noise of the ground truth: some held-out poses traced a
/// second time with independent rays. The difference of two independent
/// estimates has twice the variance of one, so the figures are the
/// difference's divided by √2: what a perfect model would still score
/// against this ground truth. Model errors close to them are noise, not
/// model error; more `--samples` lowers them.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct NoiseEstimate {
    /// Poses traced twice.
    pub frames: usize,
    /// RMSE of one ground-truth estimate.
    pub rmse: f64,
    /// Mean absolute error of one estimate.
    pub mae: f64,
    /// PSNR of one estimate against the exact AO (peak 1).
    pub psnr_db: f64,
}

impl NoiseEstimate {
    /// From `truth` rows `rows` and the same poses traced again (`again`,
    /// in that order).
    pub fn of(rows: &[usize], truth: &AoBlock, again: &AoBlock) -> Self {
        let (mut se, mut ae, mut n) = (0.0f64, 0.0f64, 0usize);
        for (k, &r) in rows.iter().enumerate() {
            for (&a, &b) in truth.row(r).iter().zip(again.row(k)) {
                let d = f64::from(a) - f64::from(b);
                se += d * d;
                ae += d.abs();
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        let mse = se / n / 2.0;
        Self {
            frames: rows.len(),
            rmse: mse.sqrt(),
            mae: ae / n / std::f64::consts::SQRT_2,
            psnr_db: psnr(mse),
        }
    }
}

/// Draws PSNR per frame over each test clip's frames (one panel per clip,
/// the model and the baseline in each, the legend above the panels) as
/// PNG bytes.
pub fn psnr_plot_png(report: &Report) -> Result<Vec<u8>, String> {
    crate::image::register_plot_font()?;
    let clips = &report.evaluation.clips;
    let (width, panel, head) = (900u32, 280u32, 64u32);
    let height = head + panel * clips.len().max(1) as u32;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let (title, body) = root.split_vertically(head);
        // What the curves are: frames of the training clips traced with
        // fresh rays (the unseen-clip folds are numbers in the report).
        title
            .draw(&Text::new(
                format!(
                    "{}: PSNR per frame of the training clips, fresh rays",
                    report.method.name()
                ),
                (12, 8),
                ("sans-serif", 20),
            ))
            .map_err(e)?;
        // The legend above the panels, where it covers no curve.
        let legend = [
            (report.method.name().to_owned(), BLUE),
            ("static average".to_owned(), RED),
        ];
        for (i, (label, colour)) in legend.into_iter().enumerate() {
            let x = 12 + 260 * i as i32;
            title
                .draw(&PathElement::new(
                    vec![(x, 46), (x + 28, 46)],
                    colour.stroke_width(3),
                ))
                .map_err(e)?;
            title
                .draw(&Text::new(label, (x + 36, 37), ("sans-serif", 16)))
                .map_err(e)?;
        }
        let panels = body.split_evenly((clips.len().max(1), 1));
        for (clip, area) in clips.iter().zip(&panels) {
            let psnr = |v: &[f64]| -> Vec<(f64, f64)> {
                clip.times
                    .iter()
                    .zip(v)
                    .map(|(&t, &p)| (f64::from(t), p))
                    .collect()
            };
            let model = psnr(&clip.errors.model.psnr_db);
            let base = psnr(&clip.errors.baseline.psnr_db);
            let all = model.iter().chain(&base).map(|p| p.1);
            let lo = all.clone().fold(f64::INFINITY, f64::min);
            let hi = all.fold(f64::NEG_INFINITY, f64::max);
            let (lo, hi) = if lo.is_finite() {
                (lo - 2.0, hi + 2.0)
            } else {
                (0.0, 1.0)
            };
            let t_max = clip.times.last().map_or(1.0, |&t| f64::from(t)).max(1e-3);
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "{}: model {:.1} dB, baseline {:.1} dB (mean)",
                        clip.clip,
                        clip.errors.model.mean.psnr_db,
                        clip.errors.baseline.mean.psnr_db
                    ),
                    ("sans-serif", 16),
                )
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(50)
                .build_cartesian_2d(0f64..t_max, lo..hi)
                .map_err(e)?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc("PSNR (dB)")
                .draw()
                .map_err(e)?;
            chart
                .draw_series(LineSeries::new(model, BLUE.stroke_width(2)))
                .map_err(e)?;
            chart
                .draw_series(LineSeries::new(base, RED.stroke_width(2)))
                .map_err(e)?;
        }
        root.present().map_err(e)?;
    }
    Ok(crate::image::encode_rgb_png(&rgb, width, height)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_of_one_estimate_is_the_difference_over_root_two() {
        let truth = AoBlock {
            vertices: 2,
            values: vec![0.5, 0.5, 0.2, 0.2],
        };
        // Row 1 traced again, off by ±0.1.
        let again = AoBlock {
            vertices: 2,
            values: vec![0.3, 0.1],
        };
        let n = NoiseEstimate::of(&[1], &truth, &again);
        assert_eq!(n.frames, 1);
        assert!((n.rmse - 0.1 / 2f64.sqrt()).abs() < 1e-7, "{n:?}");
        assert!((n.mae - 0.1 / 2f64.sqrt()).abs() < 1e-7, "{n:?}");
        assert!((n.psnr_db - 10.0 * (1.0 / 0.005f64).log10()).abs() < 1e-4);
    }
}
