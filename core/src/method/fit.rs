//! Fitting a static ground or base to ray-traced truth (the run time is
//! [`crate::method::ground`] and the grids' `base`): per receiver, the
//! offset `mean truth − k · mean model` over the training frames, with
//! `k` the least-squares gain of the truth's change on the model's. The
//! grids' base (`grid::static_base`) and the cubemaps' ground
//! (`cubemap::ground`) both fit through here.

use half::f16;

use crate::method::ground::{GroundBase, GroundSquare};

/// The least-squares gain of `truth`'s change on `model`' change, each
/// receiver's values centred on its own mean: Σ t̃·g̃ / Σ g̃², clamped to
/// [0, 2]; 1 when the model never changes. `truth` and `model` hold per
/// frame every receiver's value; `receivers` picks the ones pooled.
pub fn gain(truth: &[Vec<f32>], model: &[Vec<f32>], receivers: &[usize]) -> f32 {
    let frames = truth.len().max(1) as f64;
    let (mut cross, mut square) = (0.0f64, 0.0f64);
    for &r in receivers {
        let t_mean: f64 = truth.iter().map(|f| f64::from(f[r])).sum::<f64>() / frames;
        let g_mean: f64 = model.iter().map(|f| f64::from(f[r])).sum::<f64>() / frames;
        for (t, g) in truth.iter().zip(model) {
            let (dt, dg) = (f64::from(t[r]) - t_mean, f64::from(g[r]) - g_mean);
            cross += dt * dg;
            square += dg * dg;
        }
    }
    if square <= 1e-12 {
        1.0
    } else {
        (cross / square).clamp(0.0, 2.0) as f32
    }
}

/// Per receiver `i`, `mean truth − gain(i) · mean model` over the frames,
/// rounded to f16 as the asset stores it.
pub fn offsets(truth: &[Vec<f32>], model: &[Vec<f32>], gain: impl Fn(usize) -> f32) -> Vec<f32> {
    let n = truth.len().max(1) as f64;
    let mean =
        |v: &[Vec<f32>], i: usize| (v.iter().map(|f| f64::from(f[i])).sum::<f64>() / n) as f32;
    let receivers = truth.first().map_or(0, Vec::len);
    (0..receivers)
        .map(|i| f16::from_f32(mean(truth, i) - gain(i) * mean(model, i)).to_f32())
        .collect()
}

/// A ground texture on `square` fitted to the truth and the model at its
/// texel centres (per frame, every texel), with one gain over every texel.
pub fn ground(square: GroundSquare, truth: &[Vec<f32>], model: &[Vec<f32>]) -> GroundBase {
    let all: Vec<usize> = (0..square.texels()).collect();
    let k = gain(truth, model, &all);
    GroundBase {
        square,
        gain: k,
        offsets: offsets(truth, model, |_| k),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gain_follows_the_truths_change_and_ignores_its_level() {
        // Truth = 0.3 + 0.5·model per receiver (levels differ): gain 0.5.
        let model = vec![vec![0.1, 0.5], vec![0.3, 0.2], vec![0.2, 0.9]];
        let truth: Vec<Vec<f32>> = model
            .iter()
            .map(|f| vec![0.3 + 0.5 * f[0], 0.7 + 0.5 * f[1]])
            .collect();
        assert!((gain(&truth, &model, &[0, 1]) - 0.5).abs() < 1e-6);
        // Grids that never change leave the gain at 1.
        let flat = vec![vec![0.4, 0.4]; 3];
        assert_eq!(gain(&truth, &flat, &[0, 1]), 1.0);
        // A change against the truth's is clamped to 0.
        let against: Vec<Vec<f32>> = model.iter().map(|f| vec![-f[0], -f[1]]).collect();
        assert_eq!(gain(&truth, &against, &[0, 1]), 0.0);
    }

    #[test]
    fn offsets_carry_the_mean_truth_less_the_gained_mean_model() {
        let model = vec![vec![0.1, 0.5], vec![0.3, 0.7]];
        let truth = vec![vec![0.25, 0.5], vec![0.25, 1.0]];
        // Means: model 0.2 and 0.6, truth 0.25 and 0.75.
        let o = offsets(&truth, &model, |i| [0.0, 0.5][i]);
        assert_eq!(o, vec![0.25, f16::from_f32(0.75 - 0.3).to_f32()]);
    }
}
