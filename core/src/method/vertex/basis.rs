//! Eigen-AO: a shared basis over the vertices that a fitted vertex model
//! is compressed into.
//!
//! Across a character's vertices the AO a model predicts moves together: an
//! arm lifting lightens the armpit, the flank and the inner arm at once.
//! Over the reference poses the model's predictions `F = W C` (`P` poses ×
//! `V` vertices, `W` the poses' weights, `C` the model's coefficients) have
//! most of their variance in a few directions `R` (the leading right
//! singular vectors of `F` minus its mean `c`). Projecting the model onto
//! them,
//!
//! ```text
//! ao ≈ c + R Rᵀ (Cᵀ w − c)
//! ```
//!
//! keeps the same per-pose weights `w` but moves the product `Cᵀ w` from
//! every vertex into a small per-pose step: the CPU computes `w' = Mᵀ w −
//! o` (`M = C R / σ`, `o = Rᵀ c / σ`, `r` numbers) once per pose, and each
//! vertex takes `r + 1` multiply-adds with `[σ R; c]` instead of one per
//! weight (fewer with a threshold: each vertex then keeps only the entries
//! of `σ R` that reach it, stored sparse). It is reduced-rank regression for vertex-linear, and for
//! vertex-clustered it puts every pose cluster's blend into one basis, so
//! the per-vertex cost no longer grows with the clusters MLS blends.
//!
//! The basis rows are in AO units (`σ_j R_j`, the AO change over one
//! standard deviation of its weight), like every other block, so f16
//! holds them as well.

use faer::Mat;
use half::f16;
use serde::{Deserialize, Serialize};

pub use aobake_runtime::method::vertex::basis::Basis;

use super::{Block, FormRef, LinearForm, linalg::principal_axes_of_factor};

/// How the compression went, for the report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BasisStats {
    /// Basis rows kept.
    pub rank: usize,
    /// Weights per pose of the model before it.
    pub inputs: usize,
    /// RMS over the reference poses and vertices of what the basis leaves
    /// out of the model's predictions (its dense rows: before any
    /// threshold).
    pub rmse: f64,
    /// Fraction of the predictions' variance the basis keeps (its dense
    /// rows).
    pub kept_variance: f64,
    /// Basis entries smaller than this were dropped (0: none, the rows
    /// stored dense).
    #[serde(default)]
    pub threshold: f32,
    /// Coefficients a vertex reads: its multiply-adds.
    #[serde(default)]
    pub multiply_adds: f64,
}

/// Compresses `form` (read with the per-pose `weights` of the reference
/// poses) into at most `rank` basis rows: the basis, the one-block form of
/// `rank + 1` rows that replaces `form`, and how much was lost. `None` when
/// there are no poses or vertices, or when the predictions do not vary.
pub(super) fn compress(
    form: FormRef<'_>,
    weights: &[Vec<f32>],
    rank: usize,
) -> Option<(Basis, LinearForm, BasisStats)> {
    let c = dense(form);
    let (inputs, v, p) = (c.nrows(), c.ncols(), weights.len());
    if p == 0 || v == 0 || rank == 0 {
        return None;
    }
    // Rows R_j / σ_j, σ_j the predictions' standard deviation along R_j.
    let (mean, axes, total) = prediction_axes(&c, weights, rank);
    let r = axes.nrows();
    if r == 0 {
        // The predictions never move (AO 0 everywhere, say): nothing to
        // compress.
        return None;
    }
    let kept: f64 = (0..r)
        .map(|j| p as f64 / axes.row(j).norm_l2().powi(2))
        .sum();
    let mix = &c * axes.transpose();
    let offset: Vec<f32> = (0..r)
        .map(|j| (0..v).map(|i| mean[i] * axes[(j, i)]).sum::<f64>() as f32)
        .collect();
    let mut coefficients = Vec::with_capacity((r + 1) * v);
    for j in 0..r {
        // σ_j R_j = (R_j / σ_j) · σ_j², and σ_j² = 1 / ‖R_j / σ_j‖².
        let s2 = 1.0 / axes.row(j).norm_l2().powi(2);
        coefficients.extend((0..v).map(|i| f16::from_f64(axes[(j, i)] * s2)));
    }
    coefficients.extend(mean.iter().map(|&m| f16::from_f64(m)));
    let basis = Basis {
        inputs,
        rank: r,
        mix: (0..inputs)
            .flat_map(|k| (0..r).map(move |j| (k, j)))
            .map(|(k, j)| mix[(k, j)] as f32)
            .collect(),
        offset,
    };
    let form = LinearForm {
        vertices: v,
        blocks: vec![Block {
            rows: r + 1,
            columns: v,
            coefficients,
            map: None,
        }],
    };
    let lost = (total - kept).max(0.0);
    let stats = BasisStats {
        rank: r,
        inputs,
        rmse: (lost / (p * v) as f64).sqrt(),
        kept_variance: if total > 0.0 { kept / total } else { 1.0 },
        threshold: 0.0,
        multiply_adds: (r + 1) as f64,
    };
    Some((basis, form, stats))
}

/// The predictions `F = W C` of the coefficients `c` for the per-pose
/// `weights`: their mean over the poses (per vertex), their leading
/// `rank` principal axes (see `linalg::principal_axes`) and their total
/// variance `‖F − mean‖²`. `F` (poses × vertices) is never formed: with
/// the weights centred and factored, `W − w̄ = Q R`, the centred
/// predictions are `Q (R C)`, and `R C` (weights × vertices) has their
/// singular values and right singular vectors.
fn prediction_axes(c: &Mat<f64>, weights: &[Vec<f32>], rank: usize) -> (Vec<f64>, Mat<f64>, f64) {
    let (inputs, p) = (c.nrows(), weights.len());
    assert!(
        weights.iter().all(|w| w.len() == inputs),
        "one weight per row of the form"
    );
    let means: Vec<f64> = (0..inputs)
        .map(|k| weights.iter().map(|w| f64::from(w[k])).sum::<f64>() / p.max(1) as f64)
        .collect();
    let centred = Mat::from_fn(p, inputs, |r, k| f64::from(weights[r][k]) - means[k]);
    let w_bar = Mat::from_fn(1, inputs, |_, k| means[k]);
    let mean_row = &w_bar * c;
    let mean: Vec<f64> = (0..c.ncols()).map(|i| mean_row[(0, i)]).collect();
    let small = if p > inputs {
        centred.qr().thin_R() * c
    } else {
        &centred * c
    };
    let total = small.norm_l2().powi(2);
    (
        mean,
        principal_axes_of_factor(small.as_ref(), p, rank),
        total,
    )
}

/// The eigen-AO bases of every rank up to some most at once, for judging
/// ranks (and thresholds) against each other: what [`compress`] keeps of
/// a prediction `f` with `r` rows is `c + Σ_{j<r} a_j σ_j R_j`, `a_j =
/// (R_j / σ_j) · (f − c)`, and the axes of the smaller ranks are the first
/// of the larger. A threshold drops the entries of `σ_j R_j` (the stored
/// coefficients) below it.
#[derive(Debug, Clone)]
pub(super) struct Truncations {
    /// `c`: the mean prediction over the poses.
    mean: Vec<f64>,
    /// `M = C (R / σ)ᵀ`: a pose's weights to its coordinates (with
    /// `offset`), as the basis's own mix turns them.
    mix: Mat<f64>,
    /// `(R_j / σ_j) · c`.
    offset: Vec<f64>,
    /// `σ_j R_j`, rounded to f16 as stored, one row per axis (row-major:
    /// the sweeps read a row at a time).
    rows: Vec<Vec<f64>>,
}

impl Truncations {
    /// The axes of `form`'s predictions for the per-pose `weights`, at
    /// most `rank` of them (fewer when the predictions span fewer); `None`
    /// without poses or vertices.
    pub(super) fn new(form: FormRef<'_>, weights: &[Vec<f32>], rank: usize) -> Option<Self> {
        let c = dense(form);
        if weights.is_empty() || c.ncols() == 0 {
            return None;
        }
        let (mean, axes, _) = prediction_axes(&c, weights, rank);
        // σ_j² per axis, once per row (not once per entry: that was rank ×
        // vertices² work).
        let s2: Vec<f64> = (0..axes.nrows())
            .map(|j| 1.0 / axes.row(j).norm_l2().powi(2))
            .collect();
        let rows = (0..axes.nrows())
            .map(|j| {
                (0..axes.ncols())
                    .map(|i| f16::from_f64(axes[(j, i)] * s2[j]).to_f64())
                    .collect()
            })
            .collect();
        let mix = &c * axes.transpose();
        let offset = (0..axes.nrows())
            .map(|j| (0..mean.len()).map(|i| axes[(j, i)] * mean[i]).sum())
            .collect();
        Some(Self {
            mean,
            mix,
            offset,
            rows,
        })
    }

    /// Axes there are.
    pub(super) fn rank(&self) -> usize {
        self.rows.len()
    }

    /// The coordinates `a_j` along every axis of a pose's prediction
    /// before the clamp to [0, 1], from its weights (what the basis
    /// projects at run time).
    pub(super) fn coordinates(&self, weights: &[f32]) -> Vec<f64> {
        assert_eq!(weights.len(), self.mix.nrows(), "one weight per input");
        (0..self.rank())
            .map(|j| {
                (0..weights.len())
                    .map(|k| f64::from(weights[k]) * self.mix[(k, j)])
                    .sum::<f64>()
                    - self.offset[j]
            })
            .collect()
    }

    /// The prediction with those `coordinates` kept to its first `rank`
    /// axes (all there are, when fewer), entries below `threshold`
    /// dropped, clamped to [0, 1] as the run time does: what
    /// [`Truncations::sweep`] scores.
    #[cfg(test)]
    pub(super) fn truncate(&self, coordinates: &[f64], rank: usize, threshold: f32) -> Vec<f32> {
        let mut out = self.mean.clone();
        let t = f64::from(threshold);
        for (j, &a) in coordinates.iter().enumerate().take(rank.min(self.rank())) {
            let row = &self.rows[j];
            for (i, o) in out.iter_mut().enumerate() {
                if row[i].abs() >= t {
                    *o += a * row[i];
                }
            }
        }
        out.into_iter()
            .map(|x| (x as f32).clamp(0.0, 1.0))
            .collect()
    }

    /// Coefficients per vertex a basis of `rank` rows keeps at
    /// `threshold`, its mean's included.
    #[cfg(test)]
    pub(super) fn multiply_adds(&self, rank: usize, threshold: f32) -> f64 {
        self.costs(threshold, rank).last().copied().unwrap_or(1.0)
    }

    /// [`Truncations::multiply_adds`] of every rank from 1 to `most`.
    pub(super) fn costs(&self, threshold: f32, most: usize) -> Vec<f64> {
        let t = f64::from(threshold);
        let v = self.mean.len().max(1) as f64;
        let mut kept = 0usize;
        (0..most)
            .map(|j| {
                if j < self.rank() {
                    kept += self.rows[j].iter().filter(|x| x.abs() >= t).count();
                }
                1.0 + kept as f64 / v
            })
            .collect()
    }

    /// The squared error against `truth`, summed over the vertices, of
    /// [`Truncations::truncate`] at `threshold` for every rank from 1 to
    /// `most`, in one pass.
    pub(super) fn sweep(
        &self,
        coordinates: &[f64],
        threshold: f32,
        truth: &[f32],
        most: usize,
    ) -> Vec<f64> {
        let t = f64::from(threshold);
        let mut out = self.mean.clone();
        let mut errors = Vec::with_capacity(most);
        let axes = coordinates.iter().take(self.rank()).map(Some);
        for (j, a) in axes.chain(std::iter::repeat(None)).take(most).enumerate() {
            if let Some(&a) = a {
                let row = &self.rows[j];
                for (i, o) in out.iter_mut().enumerate() {
                    if row[i].abs() >= t {
                        *o += a * row[i];
                    }
                }
            }
            // As `truncate` rounds and clamps.
            errors.push(
                out.iter()
                    .zip(truth)
                    .map(|(&x, &y)| (f64::from((x as f32).clamp(0.0, 1.0)) - f64::from(y)).powi(2))
                    .sum(),
            );
        }
        errors
    }
}

/// The form's coefficients as a dense `weights × vertices` matrix (vertex
/// clusters expanded).
fn dense(form: FormRef<'_>) -> Mat<f64> {
    match form {
        FormRef::Dense(f) => {
            let mut c = Mat::zeros(f.weight_count(), f.vertices);
            let mut row0 = 0;
            for block in &f.blocks {
                for k in 0..block.rows {
                    let row = &block.coefficients[k * block.columns..(k + 1) * block.columns];
                    for i in 0..f.vertices {
                        let col = block.map.as_ref().map_or(i, |m| m[i] as usize);
                        c[(row0 + k, i)] = row[col].to_f64();
                    }
                }
                row0 += block.rows;
            }
            c
        }
        FormRef::Sparse(s) => {
            let mut c = Mat::zeros(s.rows, s.vertices);
            for (i, w) in s.offsets.windows(2).enumerate() {
                for e in w[0] as usize..w[1] as usize {
                    c[(usize::from(s.rows_of[e]), i)] = s.values[e].to_f64();
                }
            }
            c
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A form whose predictions over the poses span two directions: with
    /// rank 2 the compression is exact (to f16), with rank 1 it keeps the
    /// larger direction.
    #[test]
    fn a_rank_two_model_compresses_exactly_into_two_rows() {
        let v = 50;
        let (a, b): (Vec<f64>, Vec<f64>) = (0..v)
            // Multiples of 1/64 hold a + b exactly in f16.
            .map(|i| (((i * 7) % 11) as f64 / 64.0, ((i * 3) % 5) as f64 / 64.0))
            .unzip();
        // Weights [x, y, z, 1]; z moves AO along a + b.
        let mut coefficients = Vec::new();
        for k in 0..4 {
            coefficients.extend((0..v).map(|i| {
                f16::from_f64(match k {
                    0 => a[i],
                    1 => b[i],
                    2 => a[i] + b[i],
                    _ => 0.5,
                })
            }));
        }
        let form = LinearForm {
            vertices: v,
            blocks: vec![Block {
                rows: 4,
                columns: v,
                coefficients,
                map: None,
            }],
        };
        let poses: Vec<Vec<f32>> = (0..40)
            .map(|r| {
                let t = r as f32;
                vec![(t * 0.37).sin(), (t * 1.3).cos(), (t * 0.11).sin(), 1.0]
            })
            .collect();
        let (basis, small, stats) = compress(FormRef::Dense(&form), &poses, 5).unwrap();
        assert_eq!((stats.rank, basis.rank, small.weight_count()), (2, 2, 3));
        // (The RMSE is the square root of a difference of sums: rounding
        // leaves its square root.)
        assert!(
            stats.rmse < 1e-7 && (stats.kept_variance - 1.0).abs() < 1e-9,
            "{stats:?}"
        );
        for w in &poses {
            let (full, compressed) = (form.evaluate(w), small.evaluate(&basis.apply(w)));
            for (x, y) in full.iter().zip(&compressed) {
                assert!((x - y).abs() < 2e-3, "{x} vs {y}");
            }
        }
        let (one_basis, one_form, one) = compress(FormRef::Dense(&form), &poses, 1).unwrap();
        assert_eq!(one.rank, 1);
        assert!(one.rmse > 1e-3 && one.kept_variance > 0.5 && one.kept_variance < 1.0);
        // The truncations of every rank at once keep what compress keeps.
        let t = Truncations::new(FormRef::Dense(&form), &poses, 5).unwrap();
        assert_eq!(t.rank(), 2);
        let new_pose = [0.3, -0.8, 0.5, 1.0];
        let full = form.evaluate(&new_pose);
        let coordinates = t.coordinates(&new_pose);
        for (rank, (b, f)) in [(1, (&one_basis, &one_form)), (2, (&basis, &small))] {
            let kept = t.truncate(&coordinates, rank, 0.0);
            let compressed = f.evaluate(&b.apply(&new_pose));
            for (x, y) in kept.iter().zip(&compressed) {
                assert!((x - y).abs() < 2e-3, "rank {rank}: {x} vs {y}");
            }
        }
        // Past the axes there are: the prediction itself (to the f16 of
        // the stored rows).
        for (x, y) in t.truncate(&coordinates, 5, 0.0).iter().zip(&full) {
            assert!((x - y).abs() < 2e-3, "{x} vs {y}");
        }
        // A threshold over every entry leaves the mean; the entries kept
        // are what a vertex reads, its mean's included.
        assert_eq!(t.multiply_adds(2, 0.0), 3.0);
        assert_eq!(t.multiply_adds(2, 1e3), 1.0);
        // One pass scores every rank as truncating to each would.
        let truth: Vec<f32> = (0..v).map(|i| (i % 3) as f32 / 4.0).collect();
        let sse = |p: &[f32]| -> f64 {
            p.iter()
                .zip(&truth)
                .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
                .sum()
        };
        for threshold in [0.0, 0.02] {
            let swept = t.sweep(&coordinates, threshold, &truth, 4);
            let one_by_one: Vec<f64> = (1..=4)
                .map(|r| sse(&t.truncate(&coordinates, r, threshold)))
                .collect();
            assert_eq!(swept, one_by_one);
            let costs = t.costs(threshold, 4);
            assert_eq!(costs[3], costs[1], "two axes");
            assert_eq!(costs[1], t.multiply_adds(2, threshold));
        }
        let mean = t.truncate(&coordinates, 2, 1e3);
        assert!(mean.iter().zip(&t.mean).all(|(&x, &m)| x == m as f32));
    }
}
