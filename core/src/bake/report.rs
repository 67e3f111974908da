//! The report every bake carries (DESIGN §6): a JSON document and a PNG.
//! Each family's report sits beside its bake file: a per-vertex bake's
//! [`Report`] (`vertex.rs`) plots PSNR per frame over each test clip for
//! the model and the static-average baseline, as Kontkanen & Aila plot it
//! (Fig. 3); a cubemap bake's [`CubemapReport`] (`cubemap.rs`) gives every
//! encoding's errors in space and on the ground and Kroon's time ×
//! distance charts; a grid bake's [`GridReport`] (`grid.rs`) each part's
//! grid and the errors on its clip frames. Here is what they share; any of
//! them is a [`BakeReport`](super::family::BakeReport).

use serde::{Deserialize, Serialize};

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
    /// Of the two tracing times, the seconds of jobs whose process traced
    /// on a GPU (`aobake worker --gpu`, `aobake bake --tracer`): 0 when
    /// every ray was cast on the CPU. The rays are the same either way;
    /// the values can differ where a ray grazes an edge.
    #[serde(default)]
    pub gpu_trace_s: f64,
}

/// `seconds` of tracing if this process traces on a GPU, else 0.
pub(crate) fn on_gpu(seconds: f64) -> f64 {
    if crate::trace::engine::engine().is_some() {
        seconds
    } else {
        0.0
    }
}

/// The GPU tracing seconds of `deps`, summed.
pub(crate) fn gpu_seconds(deps: &[&super::JobOutput]) -> f64 {
    deps.iter().map(|d| d.timings.gpu_trace_s).sum()
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
