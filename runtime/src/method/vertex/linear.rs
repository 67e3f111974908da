//! vertex-linear (Kontkanen & Aila 2006) at run time: a pose's joint
//! angles, clamped to their ranges, turned into features, standardised
//! and projected, are the weights of the model's linear form
//! (aobake-core fits the model).

use serde::{Deserialize, Serialize};

use super::basis::Basis;
use super::form::Coefficients;
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
    pub fn expand(self, angles: &[f32], rotations: usize) -> Vec<f32> {
        match self {
            Self::RotationVector => angles.to_vec(),
            Self::Matrix => {
                let (rot, rest) = angles.split_at(3 * rotations);
                let mut out = Vec::with_capacity(self.count(angles.len(), rotations));
                for r in rot.chunks_exact(3) {
                    let m = glam::Mat3::from_quat(glam::Quat::from_scaled_axis(
                        glam::Vec3::from_slice(r),
                    )) - glam::Mat3::IDENTITY;
                    out.extend(m.to_cols_array());
                }
                out.extend_from_slice(rest);
                out
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
        assert_eq!(angles.len(), self.ranges.len(), "one number per angle");
        let clamped: Vec<f32> = angles
            .iter()
            .zip(&self.ranges)
            .map(|(&x, r)| x.clamp(r.min, r.max))
            .collect();
        let standard: Vec<f32> = self
            .features
            .expand(&clamped, self.rotations)
            .iter()
            .zip(self.mean.iter().zip(&self.inv_std))
            .map(|(&x, (&m, &s))| (x - m) * s)
            .collect();
        let mut w = match &self.projection {
            Some(d) => d
                .chunks_exact(standard.len())
                .map(|row| row.iter().zip(&standard).map(|(a, b)| a * b).sum())
                .collect(),
            None => standard,
        };
        w.push(1.0);
        match &self.basis {
            Some(b) => b.apply(&w),
            None => w,
        }
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
