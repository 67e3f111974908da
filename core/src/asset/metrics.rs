//! Error of predicted AO against ground truth (DESIGN §6), the same way for
//! every method: per frame, then summarised over frames.
//!
//! Values are occlusion (0 = open, 1 = blocked), so a prediction above the
//! truth is **too dark** and one below it is **too bright**; Kroon (2023,
//! §5.1) reports the two separately because too-dark errors show more. The
//! two squared-error parts add up to the mean squared error.

use serde::{Deserialize, Serialize};

/// PSNR of a frame with no error at all: MSE is floored at 1e-10 (100 dB)
/// so that the figure stays finite and JSON can carry it.
pub const MAX_PSNR_DB: f64 = 100.0;

/// Errors of one frame (or the mean of several frames' errors).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct FrameError {
    /// Mean absolute error per vertex.
    pub mae: f64,
    /// Root mean squared error.
    pub rmse: f64,
    /// Peak signal-to-noise ratio with peak 1, in dB: 10·log10(1 / MSE).
    pub psnr_db: f64,
    /// Mean over vertices of the squared error where the prediction is
    /// darker (more occluded) than the truth.
    pub too_dark_mse: f64,
    /// Mean over vertices of the squared error where the prediction is
    /// brighter (less occluded) than the truth.
    pub too_bright_mse: f64,
}

impl FrameError {
    /// Compares one frame. `predicted` and `truth` have the same length. A
    /// prediction that is not a finite number counts as an error of 1 (too
    /// bright), the largest an AO value can be off by.
    pub fn of(predicted: &[f32], truth: &[f32]) -> Self {
        Self::of_drawn(predicted, truth, None)
    }

    /// [`FrameError::of`] over the vertices that `drawn` marks (every one
    /// without it): a vertex that covers no pixel in the pose (see
    /// `Character::drawn_vertices`) has no AO to be right or wrong about.
    /// A frame that draws nothing has no error.
    pub fn of_drawn(predicted: &[f32], truth: &[f32], drawn: Option<&[bool]>) -> Self {
        assert_eq!(predicted.len(), truth.len(), "one value per vertex");
        if let Some(d) = drawn {
            assert_eq!(d.len(), truth.len(), "one flag per vertex");
        }
        let counted = |i: usize| drawn.is_none_or(|d| d[i]);
        let n = (0..truth.len()).filter(|&i| counted(i)).count().max(1) as f64;
        let (mut abs, mut dark, mut bright) = (0.0f64, 0.0f64, 0.0f64);
        for (i, (&p, &t)) in predicted.iter().zip(truth).enumerate() {
            if !counted(i) {
                continue;
            }
            let d = if p.is_finite() {
                f64::from(p) - f64::from(t)
            } else {
                -1.0
            };
            abs += d.abs();
            if d > 0.0 {
                dark += d * d;
            } else {
                bright += d * d;
            }
        }
        let mse = (dark + bright) / n;
        Self {
            mae: abs / n,
            rmse: mse.sqrt(),
            psnr_db: psnr(mse),
            too_dark_mse: dark / n,
            too_bright_mse: bright / n,
        }
    }
}

/// 10·log10(1 / mse), capped at [`MAX_PSNR_DB`].
pub fn psnr(mse: f64) -> f64 {
    (-10.0 * mse.max(1e-10).log10()).min(MAX_PSNR_DB)
}

/// Errors over a set of frames: the mean of the per-frame figures (so the
/// mean PSNR is the mean of per-frame PSNRs, as Kontkanen & Aila plot it)
/// and the per-frame PSNRs themselves.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Errors {
    /// Number of frames.
    pub frames: usize,
    /// Per-frame figures averaged over the frames.
    pub mean: FrameError,
    /// The worst frame's PSNR.
    pub min_psnr_db: f64,
    /// PSNR of every frame, in order.
    pub psnr_db: Vec<f64>,
}

impl Errors {
    /// Summarises per-frame errors.
    pub fn of(frames: &[FrameError]) -> Self {
        let n = frames.len().max(1) as f64;
        let sum = |f: fn(&FrameError) -> f64| frames.iter().map(f).sum::<f64>() / n;
        Self {
            frames: frames.len(),
            mean: FrameError {
                mae: sum(|e| e.mae),
                rmse: sum(|e| e.rmse),
                psnr_db: sum(|e| e.psnr_db),
                too_dark_mse: sum(|e| e.too_dark_mse),
                too_bright_mse: sum(|e| e.too_bright_mse),
            },
            min_psnr_db: frames
                .iter()
                .map(|e| e.psnr_db)
                .fold(f64::INFINITY, f64::min)
                .min(MAX_PSNR_DB),
            psnr_db: frames.iter().map(|e| e.psnr_db).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_drawn_vertices_count() {
        let (p, t) = ([0.5, 0.9, 0.3], [0.3, 0.1, 0.3]);
        let e = FrameError::of_drawn(&p, &t, Some(&[true, false, true]));
        // Two vertices judged, errors 0.2 and 0.
        assert!((e.mae - 0.1).abs() < 1e-7, "{e:?}");
        assert!((e.too_dark_mse - 0.04 / 2.0).abs() < 1e-7, "{e:?}");
        assert_eq!(FrameError::of_drawn(&p, &t, None), FrameError::of(&p, &t));
        // Nothing drawn: no error.
        let none = FrameError::of_drawn(&p, &t, Some(&[false; 3]));
        assert_eq!((none.rmse, none.psnr_db), (0.0, MAX_PSNR_DB));
    }

    #[test]
    fn splits_dark_and_bright() {
        let e = FrameError::of(&[0.5, 0.2, 0.3, 0.3], &[0.3, 0.3, 0.3, 0.3]);
        assert!((e.mae - 0.075).abs() < 1e-7);
        assert!((e.too_dark_mse - 0.04 / 4.0).abs() < 1e-7);
        assert!((e.too_bright_mse - 0.01 / 4.0).abs() < 1e-7);
        let mse: f64 = 0.05 / 4.0;
        assert!((e.rmse - mse.sqrt()).abs() < 1e-7);
        assert!((e.psnr_db - 10.0 * (1.0 / mse).log10()).abs() < 1e-4);
    }

    #[test]
    fn exact_frames_are_capped() {
        let e = FrameError::of(&[0.25; 8], &[0.25; 8]);
        assert_eq!(e.psnr_db, MAX_PSNR_DB);
        let all = Errors::of(&[e, FrameError::of(&[1.0], &[0.0])]);
        assert_eq!(all.frames, 2);
        assert_eq!(all.min_psnr_db, 0.0);
        assert_eq!(all.mean.psnr_db, 50.0);
        assert_eq!(all.psnr_db, vec![100.0, 0.0]);
    }
}
