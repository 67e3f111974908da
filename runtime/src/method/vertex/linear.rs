//! vertex-linear (Kontkanen & Aila 2006) at run time: a pose's joint
//! angles, clamped to their ranges, turned into features, standardised
//! and projected, are the weights of the model's linear form
//! (aobake-core fits the model).

use serde::{Deserialize, Serialize};

use super::basis::{Basis, finish, finished};
use super::form::Coefficients;
use super::model::StepBuffers;
use crate::pose_space::Range;

/// What vertex-linear is linear in, per rotated joint (translations are
/// always their 3 offsets).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Features {
    /// Its rotation vector r (3 numbers).
    #[default]
    RotationVector,
    /// Its rotation matrix R(r) − I, column-major (9 numbers).
    Matrix,
}

impl Features {
    /// Features per rotated joint.
    fn per_rotation(self) -> usize {
        match self {
            Self::RotationVector => 3,
            Self::Matrix => 9,
        }
    }

    /// How many features `angles` angles with `rotations` rotated joints
    /// give.
    pub fn count(self, angles: usize, rotations: usize) -> usize {
        angles - 3 * rotations + self.per_rotation() * rotations
    }

    /// The features of a joint-angle vector.
    /// (Computed in double precision and rounded.)
    pub fn expand(self, angles: &[f32], rotations: usize) -> Vec<f32> {
        let angles: Vec<f64> = angles.iter().map(|&a| f64::from(a)).collect();
        self.expand_f64(&angles, rotations)
            .into_iter()
            .map(|x| x as f32)
            .collect()
    }

    /// [`Features::expand`] in double precision.
    pub fn expand_f64(self, angles: &[f64], rotations: usize) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.count(angles.len(), rotations));
        self.expand_f64_into(angles, rotations, &mut out);
        out
    }

    /// [`Features::expand_f64`] into `out` (cleared first).
    pub fn expand_f64_into(self, angles: &[f64], rotations: usize, out: &mut Vec<f64>) {
        out.clear();
        match self {
            Self::RotationVector => out.extend_from_slice(angles),
            Self::Matrix => {
                let (rot, rest) = angles.split_at(3 * rotations);
                for r in rot.chunks_exact(3) {
                    let m = glam::DMat3::from_quat(glam::DQuat::from_scaled_axis(
                        glam::DVec3::from_slice(r),
                    )) - glam::DMat3::IDENTITY;
                    out.extend(m.to_cols_array());
                }
                out.extend_from_slice(rest);
            }
        }
    }

    /// The features that angles `params` (sorted) drive, sorted.
    pub fn expand_indices(self, params: &[usize], rotations: usize) -> Vec<usize> {
        let k = self.per_rotation();
        let mut out: Vec<usize> = params
            .iter()
            .flat_map(|&p| {
                if p < 3 * rotations {
                    let j = p / 3;
                    match self {
                        Self::RotationVector => p..p + 1,
                        Self::Matrix => k * j..k * j + k,
                    }
                } else {
                    let f = p - 3 * rotations + k * rotations;
                    f..f + 1
                }
            })
            .collect();
        out.dedup();
        out
    }
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
    /// Features (N) the model is linear in.
    pub parameters: usize,
    /// What they are.
    pub features: Features,
    /// Rotated joints among the angles.
    pub rotations: usize,
    /// With matrix features: the leading principal directions of the
    /// standardised features, row-major `parameters × features`; the
    /// model is linear in the projections onto them.
    pub projection: Option<Vec<f32>>,
    /// μ_k: mean of each feature over the reference poses.
    pub mean: Vec<f32>,
    /// 1/σ_k, or 0 for a feature that never moved (its column is left
    /// out).
    pub inv_std: Vec<f32>,
    /// The valid range of each angle (from the clips, with the margin):
    /// angles are clamped to it at run time, so a pose outside what the
    /// model was fitted on does not extrapolate a linear function without
    /// bound.
    pub ranges: Vec<Range>,
    /// `T` in f16: N+1 rows (the standardised features, then the
    /// constant); with a basis, its `r + 1` rows.
    pub coefficients: Coefficients,
    /// The eigen-AO basis the model was compressed into, if any: the
    /// weights above go through it.
    pub basis: Option<Basis>,
}

impl VertexLinear {
    /// The weights of a pose: its joint angles clamped to their ranges,
    /// turned into features and standardised, and a 1.
    pub fn weights(&self, angles: &[f32]) -> Vec<f32> {
        let angles: Vec<f64> = angles.iter().map(|&a| f64::from(a)).collect();
        self.weights_f64(&angles)
    }

    /// [`VertexLinear::weights`] of unrounded joint angles, computed in
    /// double precision (features, standardising, projection, basis) and
    /// rounded once at the end: the inverse standard deviation of a joint
    /// that barely moved can be 10⁵, which would make single precision's
    /// rounding along the way visible in the AO.
    pub fn weights_f64(&self, angles: &[f64]) -> Vec<f32> {
        finished(&self.unrounded_weights(angles), self.basis.as_ref())
    }

    /// [`VertexLinear::weights_f64`] into `out` (one value per weight),
    /// with buffers that allocate nothing once they have held a pose.
    pub(crate) fn weights_f64_into(&self, angles: &[f64], b: &mut StepBuffers, out: &mut [f32]) {
        b.unrounded.clear();
        self.unrounded_weights_into(angles, &mut b.linear, &mut b.unrounded);
        finish(&b.unrounded, self.basis.as_ref(), &mut b.basis, out);
    }

    /// The weights before the basis, unrounded (what vertex-clustered's
    /// linear base contributes).
    pub fn unrounded_weights(&self, angles: &[f64]) -> Vec<f64> {
        let mut out = Vec::new();
        self.unrounded_weights_into(angles, &mut Default::default(), &mut out);
        out
    }

    /// [`VertexLinear::unrounded_weights`] appended to `out`, with two
    /// buffers for the clamped angles and their features.
    pub(crate) fn unrounded_weights_into(
        &self,
        angles: &[f64],
        [clamped, standard]: &mut [Vec<f64>; 2],
        out: &mut Vec<f64>,
    ) {
        assert_eq!(angles.len(), self.ranges.len(), "one number per angle");
        clamped.clear();
        clamped.extend(
            angles
                .iter()
                .zip(&self.ranges)
                .map(|(&x, r)| x.clamp(f64::from(r.min), f64::from(r.max))),
        );
        self.features
            .expand_f64_into(clamped, self.rotations, standard);
        // One feature per mean and scale (an asset's reader checks they
        // agree).
        standard.truncate(self.mean.len().min(self.inv_std.len()));
        standard
            .iter_mut()
            .zip(self.mean.iter().zip(&self.inv_std))
            .for_each(|(x, (&m, &s))| *x = (*x - f64::from(m)) * f64::from(s));
        match &self.projection {
            Some(d) => out.extend(d.chunks_exact(standard.len()).map(|row| {
                row.iter()
                    .zip(standard.iter())
                    .map(|(&a, b)| f64::from(a) * b)
                    .sum::<f64>()
            })),
            None => out.extend_from_slice(standard),
        }
        out.push(1.0);
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
            Coefficients::Dense(f) => f.weight_count() as f64,
            Coefficients::Sparse(s) => s.multiply_adds(),
        }
    }

    /// Coefficient bytes and the angles' means and scales.
    pub fn bytes(&self) -> usize {
        8 * self.mean.len()
            + 4 * self.projection.as_ref().map_or(0, Vec::len)
            + self.basis.as_ref().map_or(0, Basis::bytes)
            + self.coefficients.bytes()
    }
}
