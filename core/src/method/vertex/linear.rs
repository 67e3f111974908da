//! vertex-linear (Kontkanen & Aila 2006): per-vertex AO as a linear
//! function of the joint angles, `a_v = jᵀ t_v` with `j = [angles…, 1]`,
//! fitted over reference poses by least squares (DESIGN §5).

use faer::Mat;
use half::f16;
use serde::{Deserialize, Serialize};

use super::cv::RidgeChoice;
use super::form::{Block, LinearForm, SparseForm};
use super::linalg::{SolveStats, ridge_lstsq};
use crate::{pose_space::Range, trace::AoBlock};

/// The default ridge weight: on standardised angles it shrinks directions
/// of pose space with less than about 1/1000 of a typical angle's variance
/// (correlated angles in clip frames), and leaves well-spread random poses
/// all but untouched (a factor 1/(1 + 0.001)).
pub const DEFAULT_RIDGE: f64 = 1e-3;

/// Fitting options of vertex-linear.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinearOptions {
    /// Ridge (Tikhonov) weight λ on the coefficients of the standardised
    /// joint angles, per reference pose: minimises `(1/P)‖J T − A‖² +
    /// λ‖T‖²`. The constant column is not penalised. 0 gives the
    /// pseudo-inverse solution.
    pub ridge: f64,
    /// Coefficients of the standardised joint angles (AO change per
    /// standard deviation of the angle) with a magnitude below this are
    /// dropped and the rest stored sparse (CSR per vertex). 0 keeps the
    /// dense matrix.
    pub threshold: f32,
    /// Choose the ridge weight by cross-validation over clips: each
    /// candidate of [`RIDGE_CANDIDATES`] is fitted without the reference
    /// frames of one group of clips at a time and scored on them (up to
    /// [`super::cv::CV_FOLDS`] groups); the one with the least squared
    /// error wins. `ridge` is used when the reference frames come from
    /// fewer than two clips.
    pub ridge_cv: bool,
    /// Locality: with `on`, each vertex depends only on the parameters of
    /// the joints that skin it and their neighbours on the skeleton
    /// (`JointAngles::local_parameters`), the others' coefficients are
    /// zero and the model is stored sparse; `cv` lets the cross-validation
    /// over clips choose between that and every parameter (`off`).
    pub locality: Locality,
}

/// Whether vertex-linear's vertices see every parameter or only their
/// joints' neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Locality {
    /// Every parameter (Kontkanen & Aila).
    Off,
    /// The parameters of the joints near each vertex.
    On,
    /// Whichever scores better over left-out clips (`off` when the
    /// reference frames come from fewer than two clips).
    Cv,
}

impl Default for LinearOptions {
    fn default() -> Self {
        Self {
            ridge: DEFAULT_RIDGE,
            threshold: 0.0,
            ridge_cv: true,
            locality: Locality::Cv,
        }
    }
}

/// The ridge weights cross-validation chooses from.
pub const RIDGE_CANDIDATES: [f64; 6] = [1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0];

/// Chooses vertex-linear's ridge weight by leaving groups of clips out
/// (see [`super::cv::choose_by_clips`]); `None` when the rows come from
/// fewer than two clips.
pub fn choose_ridge(
    poses: &[Vec<f32>],
    ranges: &[Range],
    ao: &AoBlock,
    groups: &[Option<usize>],
    options: &LinearOptions,
    local: Option<&[Vec<usize>]>,
) -> Option<RidgeChoice> {
    super::cv::choose_by_clips(
        groups,
        ao,
        &RIDGE_CANDIDATES,
        |train| {
            let q: Vec<Vec<f32>> = train.iter().map(|&r| poses[r].clone()).collect();
            let block = ao.select(train.iter().copied());
            RIDGE_CANDIDATES
                .iter()
                .map(|&ridge| {
                    let o = LinearOptions {
                        ridge,
                        ridge_cv: false,
                        ..*options
                    };
                    VertexLinear::fit(&q, ranges, &block, &o, local)
                        .ok()
                        .map(|(m, _)| m)
                })
                .collect()
        },
        |model, r| model.evaluate(&poses[r]),
    )
}

/// The stored coefficients: dense `(N+1) × V`, or sparse per vertex.
#[derive(Debug, Clone, PartialEq)]
pub enum Coefficients {
    /// All coefficients.
    Dense(LinearForm),
    /// Coefficients over the threshold, and every constant term.
    Sparse(SparseForm),
}

/// A fitted vertex-linear model.
///
/// The joint angles enter standardised, `(j_k − μ_k) / σ_k` over the
/// reference poses, which is the same linear model as Kontkanen & Aila's
/// `jᵀt` (an affine change of the pose vector, still with the constant
/// column) but puts every coefficient in AO units (the AO change over one
/// standard deviation of that angle). That keeps f16 storage accurate (no
/// large terms cancelling against the constant), makes the ridge weight and
/// the sparsification threshold unit-free, and makes the constant the mean
/// AO.
#[derive(Debug, Clone, PartialEq)]
pub struct VertexLinear {
    /// Joint-angle parameters (N).
    pub parameters: usize,
    /// μ_k: mean of each angle over the reference poses.
    pub mean: Vec<f32>,
    /// 1/σ_k, or 0 for an angle that never moved (its column is left out).
    pub inv_std: Vec<f32>,
    /// The valid range of each angle (from the clips, with the margin):
    /// angles are clamped to it at run time, so a pose outside what the
    /// model was fitted on does not extrapolate a linear function without
    /// bound.
    pub ranges: Vec<Range>,
    /// `T` in f16: N+1 rows (the standardised angles, then the constant).
    pub coefficients: Coefficients,
}

/// What the fit did, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearFitStats {
    /// The solve of the standardised joint-angle matrix.
    pub solve: SolveStats,
    /// Angles that never moved over the reference poses (left out).
    pub constant_parameters: usize,
    /// RMSE over the training poses of the f64 fit, before f16 rounding
    /// and sparsification.
    pub training_rmse: f64,
    /// RMSE over the training poses of the stored model (f16, sparse).
    pub stored_training_rmse: f64,
    /// Coefficients kept / all coefficients.
    pub kept_fraction: f64,
    /// The ridge weight fitted with.
    #[serde(default)]
    pub ridge: f64,
    /// How cross-validation over clips chose it, when it did.
    #[serde(default)]
    pub ridge_cv: Option<super::cv::RidgeChoice>,
    /// Whether the model is local (each vertex on its joints' parameters).
    #[serde(default)]
    pub local: bool,
}

/// A fit whose coefficients f16 cannot hold.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the fit is ill-conditioned: a coefficient of {largest:e} does not fit in f16; use more reference poses than parameters ({parameters}) or a ridge weight"
)]
pub struct FitOverflow {
    /// The largest coefficient magnitude.
    pub largest: f64,
    /// The number of parameters.
    pub parameters: usize,
}

/// The largest value an f16 holds.
pub(crate) const F16_MAX: f64 = 65504.0;

impl VertexLinear {
    /// Fits `T = J⁺A` over `poses` (one joint-angle vector per row of
    /// `ao`), on standardised angles; the constant column, the mean AO, is
    /// never penalised by the ridge. The solve goes through an SVD (see
    /// [`ridge_lstsq`]).
    pub fn fit(
        poses: &[Vec<f32>],
        ranges: &[Range],
        ao: &AoBlock,
        options: &LinearOptions,
        local: Option<&[Vec<usize>]>,
    ) -> Result<(Self, LinearFitStats), FitOverflow> {
        let p = poses.len();
        assert_eq!(p, ao.poses(), "one pose per AO row");
        assert!(p > 0, "at least one reference pose");
        let n = poses[0].len();
        assert_eq!(ranges.len(), n, "one range per parameter");
        let v = ao.vertices;
        let mean_j: Vec<f64> = (0..n)
            .map(|k| poses.iter().map(|q| f64::from(q[k])).sum::<f64>() / p as f64)
            .collect();
        let inv_std: Vec<f64> = (0..n)
            .map(|k| {
                let var = poses
                    .iter()
                    .map(|q| (f64::from(q[k]) - mean_j[k]).powi(2))
                    .sum::<f64>()
                    / p as f64;
                // An angle that moved less than this (radians) is constant.
                if var.sqrt() > 1e-6 {
                    1.0 / var.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let mean_a = ao.mean();
        let js = Mat::from_fn(p, n, |r, k| {
            (f64::from(poses[r][k]) - mean_j[k]) * inv_std[k]
        });
        let ac = Mat::from_fn(p, v, |r, i| f64::from(ao.row(r)[i]) - mean_a[i]);
        let lambda = options.ridge * p as f64;
        let (t, solve) = match local {
            None => ridge_lstsq(js.as_ref(), ac.as_ref(), lambda),
            Some(local) => {
                // The whole design's conditioning for the report (an SVD
                // with no targets), then one solve per distinct set of
                // local parameters over the vertices that share it.
                let (_, solve) = ridge_lstsq(js.as_ref(), Mat::<f64>::zeros(p, 0).as_ref(), lambda);
                let mut sets: std::collections::BTreeMap<&[usize], Vec<usize>> = Default::default();
                for (i, params) in local.iter().enumerate().take(v) {
                    sets.entry(params.as_slice()).or_default().push(i);
                }
                let mut t = Mat::zeros(n, v);
                for (params, vertices) in sets.into_iter().filter(|(s, _)| !s.is_empty()) {
                    let d = Mat::from_fn(p, params.len(), |r, c| js[(r, params[c])]);
                    let y = Mat::from_fn(p, vertices.len(), |r, c| ac[(r, vertices[c])]);
                    let (x, _) = ridge_lstsq(d.as_ref(), y.as_ref(), lambda);
                    for (c, &i) in vertices.iter().enumerate() {
                        for (row, &k) in params.iter().enumerate() {
                            t[(k, i)] = x[(row, c)];
                        }
                    }
                }
                (t, solve)
            }
        };
        let largest = (0..n)
            .flat_map(|k| (0..v).map(move |i| (k, i)))
            .map(|(k, i)| t[(k, i)].abs())
            .fold(0.0f64, f64::max);
        if largest.is_nan() || largest > F16_MAX {
            return Err(FitOverflow {
                largest,
                parameters: n,
            });
        }
        let mut coefficients = Vec::with_capacity((n + 1) * v);
        for k in 0..n {
            coefficients.extend((0..v).map(|i| f16::from_f64(t[(k, i)])));
        }
        coefficients.extend(mean_a.iter().map(|&c| f16::from_f64(c)));
        let block = Block {
            rows: n + 1,
            columns: v,
            coefficients,
            map: None,
        };
        let threshold = match (local.is_some(), options.threshold > 0.0) {
            (_, true) => options.threshold,
            // Locality: the coefficients outside a vertex's set are zero.
            (true, false) => f32::MIN_POSITIVE,
            (false, false) => 0.0,
        };
        let (stored, kept_fraction) = if threshold > 0.0 {
            let sparse = SparseForm::from_dense(&block, v, threshold, &[n]);
            let kept = sparse.values.len() as f64 / ((n + 1) * v).max(1) as f64;
            (Coefficients::Sparse(sparse), kept)
        } else {
            (
                Coefficients::Dense(LinearForm {
                    vertices: v,
                    blocks: vec![block],
                }),
                1.0,
            )
        };
        let model = Self {
            parameters: n,
            mean: mean_j.iter().map(|&x| x as f32).collect(),
            inv_std: inv_std.iter().map(|&x| x as f32).collect(),
            ranges: ranges.to_vec(),
            coefficients: stored,
        };
        let (mut exact, mut rounded) = (0.0f64, 0.0f64);
        for (r, q) in poses.iter().enumerate() {
            let predicted = model.evaluate(q);
            for (i, (&truth, &pred)) in ao.row(r).iter().zip(&predicted).enumerate() {
                let f = mean_a[i] + (0..n).map(|k| js[(r, k)] * t[(k, i)]).sum::<f64>();
                exact += (f - f64::from(truth)).powi(2);
                rounded += (f64::from(pred) - f64::from(truth)).powi(2);
            }
        }
        let count = (p * v).max(1) as f64;
        let stats = LinearFitStats {
            solve,
            constant_parameters: inv_std.iter().filter(|&&s| s == 0.0).count(),
            training_rmse: (exact / count).sqrt(),
            stored_training_rmse: (rounded / count).sqrt(),
            kept_fraction,
            ridge: options.ridge,
            ridge_cv: None,
            local: local.is_some(),
        };
        Ok((model, stats))
    }

    /// The weights of a pose: its joint angles clamped to their ranges and
    /// standardised, and a 1.
    pub fn weights(&self, angles: &[f32]) -> Vec<f32> {
        assert_eq!(angles.len(), self.parameters, "one number per parameter");
        let mut w: Vec<f32> = angles
            .iter()
            .zip(&self.ranges)
            .zip(self.mean.iter().zip(&self.inv_std))
            .map(|((&x, r), (&m, &s))| (x.clamp(r.min, r.max) - m) * s)
            .collect();
        w.push(1.0);
        w
    }

    /// AO of every vertex at these joint angles.
    pub fn evaluate(&self, angles: &[f32]) -> Vec<f32> {
        let w = self.weights(angles);
        match &self.coefficients {
            Coefficients::Dense(form) => form.evaluate(&w),
            Coefficients::Sparse(form) => form.evaluate(&w),
        }
    }

    /// Multiply-adds per vertex at run time (mean over vertices if sparse).
    pub fn multiply_adds(&self) -> f64 {
        match &self.coefficients {
            Coefficients::Dense(_) => (self.parameters + 1) as f64,
            Coefficients::Sparse(s) => s.values.len() as f64 / s.vertices.max(1) as f64,
        }
    }

    /// Coefficient bytes and the angles' means and scales.
    pub fn bytes(&self) -> usize {
        8 * self.parameters
            + match &self.coefficients {
                Coefficients::Dense(f) => f.bytes(),
                Coefficients::Sparse(s) => s.bytes(),
            }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt as _, SeedableRng as _};
    use rand_chacha::ChaCha8Rng;

    fn wide() -> Vec<Range> {
        vec![
            Range {
                min: -2.0,
                max: 2.0
            };
            3
        ]
    }

    /// AO that is exactly linear in 3 parameters, plus a vertex that
    /// ignores them.
    fn linear_data(poses: usize) -> (Vec<Vec<f32>>, AoBlock) {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let q: Vec<Vec<f32>> = (0..poses)
            .map(|_| (0..3).map(|_| rng.random_range(-1.0f32..1.0)).collect())
            .collect();
        let mut values = Vec::new();
        for x in &q {
            values.push(0.5 + 0.1 * x[0] - 0.05 * x[2]);
            values.push(0.25);
            values.push(0.3 + 0.2 * x[1]);
        }
        (
            q,
            AoBlock {
                vertices: 3,
                values,
            },
        )
    }

    #[test]
    fn recovers_linear_ao_on_unseen_poses() {
        let (q, ao) = linear_data(40);
        let exact = LinearOptions {
            ridge: 0.0,
            ..LinearOptions::default()
        };
        let (model, stats) = VertexLinear::fit(&q, &wide(), &ao, &exact, None).unwrap();
        assert_eq!(stats.solve.rank, 3);
        assert!(stats.training_rmse < 1e-6, "{stats:?}");
        assert!(
            stats.stored_training_rmse < 1e-3,
            "f16 rounding only: {stats:?}"
        );
        let ao = model.evaluate(&[0.5, -0.5, 1.0]);
        let want = [0.5 + 0.05 - 0.05, 0.25, 0.3 - 0.1];
        for (a, b) in ao.iter().zip(want) {
            assert!((a - b).abs() < 1e-3, "{ao:?}");
        }
        assert_eq!(model.multiply_adds(), 4.0);
        // Outside its range an angle is clamped: 3 counts as 2.
        assert_eq!(
            model.evaluate(&[3.0, 0.0, 0.0]),
            model.evaluate(&[2.0, 0.0, 0.0])
        );
        assert_eq!(model.bytes(), 2 * 4 * 3 + 8 * 3);
    }

    #[test]
    fn threshold_drops_small_coefficients_and_ridge_shrinks() {
        let (q, ao) = linear_data(40);
        let options = LinearOptions {
            threshold: 0.01,
            ..LinearOptions::default()
        };
        let (model, stats) = VertexLinear::fit(&q, &wide(), &ao, &options, None).unwrap();
        // 3 of the 9 angle coefficients are non-zero, plus 3 constants.
        let Coefficients::Sparse(s) = &model.coefficients else {
            panic!("sparse expected")
        };
        assert_eq!(s.values.len(), 3 + 3);
        assert!((stats.kept_fraction - 0.5).abs() < 1e-9);
        assert!(stats.stored_training_rmse < 1e-3);
        let (ridged, rs) = VertexLinear::fit(
            &q,
            &wide(),
            &ao,
            &LinearOptions {
                ridge: 1.0,
                ..LinearOptions::default()
            },
            None,
        )
        .unwrap();
        assert!(rs.training_rmse > 1e-3, "ridge trades fit for smaller T");
        let slope = ridged.evaluate(&[1.0, 0.0, 0.0])[0] - ridged.evaluate(&[0.0, 0.0, 0.0])[0];
        assert!(slope > 0.0 && slope < 0.1, "{slope}");
    }
}
