//! vertex-clustered (Kirk & Arikan 2007) at run time: a pose's handle
//! vector is blended over the pose clusters by moving least squares
//! (Eq. 5) and projected onto each cluster's whitened principal axes; the
//! blended projections are the weights of the model's linear form
//! (aobake-core fits the model).

use serde::{Deserialize, Serialize};

use super::basis::{Basis, finish, finished};
use super::form::Coefficients;
use super::linear::VertexLinear;
use super::model::StepBuffers;
use crate::pose_space::JointAngles;

/// MLS weights below this are dropped (and the rest renormalised), so a
/// pose pays only for the handful of clusters it is near (with α = 10 the
/// others contribute less than f16 can hold anyway).
pub const MIN_BLEND_WEIGHT: f64 = 1e-4;

/// What each pose cluster's linear model is centred on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Centering {
    /// The paper's Eq. 1: AO minus the global mean, no constant term.
    Global,
    /// A constant per vertex and cluster as well (one more coefficient).
    #[default]
    Cluster,
}

/// A vertex-linear base: the joint angles it reads and how it turns them
/// into weights. Its coefficients are block 0 of the clustered form (the
/// `VertexLinear`'s own are empty).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearBase {
    /// The joint angles.
    pub joint_angles: JointAngles,
    /// Ranges, features, projection, means and scales of the weights.
    pub weights: VertexLinear,
}

/// One pose cluster's centre and PCA projection.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseCluster {
    /// h̄_j, the mean handle vector of the cluster's poses.
    pub center: Vec<f32>,
    /// P_j: `dimensions × handles` row-major, each row a principal axis
    /// divided by the standard deviation along it (so projections are
    /// whitened); rows past the cluster's rank are zero.
    pub axes: Vec<f32>,
}

/// A fitted vertex-clustered model.
#[derive(Debug, Clone, PartialEq)]
pub struct VertexClustered {
    /// Numbers per handle vector.
    pub handles: usize,
    /// n.
    pub dimensions: usize,
    /// α.
    pub alpha: f32,
    /// Centring (whether each cluster block has a constant row).
    pub centering: Centering,
    /// Clamp of the whitened coordinates (0: none).
    pub clamp: f32,
    /// The pose clusters.
    pub clusters: Vec<PoseCluster>,
    /// Block 0: the global mean AO (or with a linear base, its
    /// coefficients: a row per weight, the last the constant); block 1 + j:
    /// pose cluster j's coefficients (`n` rows, plus the constant row with
    /// [`Centering::Cluster`]), per vertex or per vertex cluster. With a
    /// basis, its one block, dense or with small entries dropped.
    pub form: Coefficients,
    /// The vertex-linear base, if any (see [`Base`]).
    pub base: Option<Box<LinearBase>>,
    /// The eigen-AO basis the model was compressed into, if any: the
    /// weights above go through it, and `form` is its rows.
    pub basis: Option<Basis>,
}

impl VertexClustered {
    /// Rows per pose-cluster block.
    pub fn rows(&self) -> usize {
        self.dimensions + usize::from(self.centering == Centering::Cluster)
    }

    /// Kirk & Arikan's Eq. 5: normalised ‖h − h̄_j‖^(−α), computed in logs
    /// so that neither tiny nor huge distances overflow; weights under
    /// [`MIN_BLEND_WEIGHT`] are dropped and the rest renormalised. A pose
    /// on a centre takes that cluster alone.
    pub fn blend_weights(&self, h: &[f32]) -> Vec<f64> {
        let h: Vec<f64> = h.iter().map(|&x| f64::from(x)).collect();
        self.blend_weights_f64(&h)
    }

    /// [`VertexClustered::blend_weights`] of an unrounded handle vector.
    pub fn blend_weights_f64(&self, h: &[f64]) -> Vec<f64> {
        let mut w = Vec::with_capacity(self.clusters.len());
        self.blend_weights_f64_into(h, &mut w);
        w
    }

    /// [`VertexClustered::blend_weights_f64`] into `w` (cleared first).
    pub(crate) fn blend_weights_f64_into(&self, h: &[f64], w: &mut Vec<f64>) {
        w.clear();
        // Squared distances to the centres, then in place their logs'
        // weights.
        w.extend(self.clusters.iter().map(|c| {
            c.center
                .iter()
                .zip(h)
                .map(|(&a, &b)| (b - f64::from(a)).powi(2))
                .sum::<f64>()
        }));
        if let Some(hit) = w.iter().position(|&d| d == 0.0) {
            for (j, x) in w.iter_mut().enumerate() {
                *x = f64::from(j == hit);
            }
            return;
        }
        let alpha = f64::from(self.alpha);
        w.iter_mut().for_each(|d| *d = -0.5 * alpha * d.ln());
        let top = w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        w.iter_mut().for_each(|l| *l = (*l - top).exp());
        let sum: f64 = w.iter().sum();
        w.iter_mut().for_each(|x| *x /= sum);
        w.iter_mut()
            .filter(|x| **x < MIN_BLEND_WEIGHT)
            .for_each(|x| *x = 0.0);
        let sum: f64 = w.iter().sum();
        w.iter_mut().for_each(|x| *x /= sum);
    }

    /// The per-pose weights of the linear form: `[1]` for the mean, then
    /// per cluster `ω_j · P_j (h − h̄_j)`, each coordinate clamped to
    /// ±`clamp` (and `ω_j` for the constant).
    pub fn weights(&self, h: &[f32]) -> Vec<f32> {
        assert!(self.base.is_none(), "a linear base needs the joint angles");
        self.weights_with(h, &[])
    }

    /// [`VertexClustered::weights`] with a linear base: its weights of
    /// `angles` (ignored without a base) first.
    pub fn weights_with(&self, h: &[f32], angles: &[f32]) -> Vec<f32> {
        let angles: Vec<f64> = angles.iter().map(|&a| f64::from(a)).collect();
        let h: Vec<f64> = h.iter().map(|&x| f64::from(x)).collect();
        self.weights_with_f64(&h, &angles)
    }

    /// [`VertexClustered::weights_with`] of unrounded handles and joint
    /// angles, in double precision until the end.
    pub fn weights_with_f64(&self, h: &[f64], angles: &[f64]) -> Vec<f32> {
        let mut b = StepBuffers::default();
        self.unrounded_weights_into(h, angles, &mut b);
        finished(&b.unrounded, self.basis.as_ref())
    }

    /// [`VertexClustered::weights_with_f64`] into `out` (one value per
    /// weight), with buffers that allocate nothing once they have held a
    /// pose.
    pub(crate) fn weights_with_f64_into(
        &self,
        h: &[f64],
        angles: &[f64],
        b: &mut StepBuffers,
        out: &mut [f32],
    ) {
        self.unrounded_weights_into(h, angles, b);
        finish(&b.unrounded, self.basis.as_ref(), &mut b.basis, out);
    }

    /// The weights before the basis, unrounded, into `b.unrounded`.
    fn unrounded_weights_into(&self, h: &[f64], angles: &[f64], b: &mut StepBuffers) {
        assert_eq!(h.len(), self.handles, "one number per handle coordinate");
        self.blend_weights_f64_into(h, &mut b.omega);
        let out = &mut b.unrounded;
        out.clear();
        match &self.base {
            Some(base) => base
                .weights
                .unrounded_weights_into(angles, &mut b.linear, out),
            None => out.push(1.0),
        }
        for (cluster, &w) in self.clusters.iter().zip(&b.omega) {
            for r in 0..self.dimensions {
                let axis = &cluster.axes[r * self.handles..(r + 1) * self.handles];
                let y: f64 = axis
                    .iter()
                    .zip(h.iter().zip(&cluster.center))
                    .map(|(&a, (&x, &c))| f64::from(a) * (x - f64::from(c)))
                    .sum();
                let y = if self.clamp > 0.0 {
                    let c = f64::from(self.clamp);
                    y.clamp(-c, c)
                } else {
                    y
                };
                out.push(w * y);
            }
            if self.centering == Centering::Cluster {
                out.push(w);
            }
        }
    }

    /// AO of every vertex for a handle vector (Eq. 4).
    pub fn evaluate(&self, h: &[f32]) -> Vec<f32> {
        self.form.evaluate(&self.weights(h))
    }

    /// Bytes of the model: coefficients and maps, centres and axes (f32).
    pub fn bytes(&self) -> usize {
        self.form.bytes()
            + self.clusters.len() * 4 * (self.handles * (1 + self.dimensions))
            + self.base.as_ref().map_or(0, |b| b.weights.bytes())
            + self.basis.as_ref().map_or(0, Basis::bytes)
    }
}
