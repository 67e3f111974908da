//! A vertex model as an asset holds it: the fitted model and the pose
//! features it reads, evaluated per pose from the nodes' local transforms.

use super::{FormRef, average::StaticAverage, clustered::VertexClustered, linear::VertexLinear};
use glam::DAffine3;

use crate::{
    Method,
    pose_space::{Handles, JointAngles},
    rig::{Skeleton, Transform},
};

/// A fitted model and the pose features it reads.
#[derive(Debug, Clone, PartialEq)]
pub enum Model {
    /// The baseline.
    StaticAverage(StaticAverage),
    /// Kontkanen & Aila, over these joint angles.
    VertexLinear(JointAngles, VertexLinear),
    /// Kirk & Arikan, over these handles.
    VertexClustered(Handles, VertexClustered),
}

impl Model {
    /// The method.
    pub fn method(&self) -> Method {
        match self {
            Self::StaticAverage(_) => Method::StaticAverage,
            Self::VertexLinear(..) => Method::VertexLinear,
            Self::VertexClustered(..) => Method::VertexClustered,
        }
    }

    /// Vertices the model covers.
    pub fn vertices(&self) -> usize {
        match self {
            Self::StaticAverage(m) => m.form.vertices,
            Self::VertexLinear(_, m) => m.coefficients.vertices(),
            Self::VertexClustered(_, m) => m.form.vertices(),
        }
    }

    /// The coefficients as the run time sees them: a dense linear form or a
    /// sparse one, taking [`Model::weights`].
    pub fn form(&self) -> FormRef<'_> {
        match self {
            Self::StaticAverage(m) => FormRef::Dense(&m.form),
            Self::VertexLinear(_, m) => m.coefficients.as_ref(),
            Self::VertexClustered(_, m) => m.form.as_ref(),
        }
    }

    /// Weights per pose: the length of [`Model::weights`].
    pub fn weight_count(&self) -> usize {
        self.form().weight_count()
    }

    /// Bytes of the model's numbers: coefficients, maps, cluster centres
    /// and axes.
    pub fn bytes(&self) -> usize {
        match self {
            Self::StaticAverage(m) => m.form.bytes(),
            Self::VertexLinear(_, m) => m.bytes(),
            Self::VertexClustered(_, m) => m.bytes(),
        }
    }

    /// The per-pose weights (joint angles and a 1, blended projections, or
    /// `[1]`), computed once per pose on the CPU, in double precision from
    /// the local transforms on and rounded once at the end.
    ///
    /// A degenerate pose (a node scaled to zero above the body root, whose
    /// frame the handles are measured in; transforms of infinite size)
    /// gives features that are not numbers: each weight that is not a
    /// finite number counts as 0, so the AO stays a number in [0, 1].
    pub fn weights(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f32> {
        let mut out = vec![0.0; self.weight_count()];
        self.weights_into(skeleton, locals, &mut PoseScratch::default(), &mut out);
        out
    }

    /// [`Model::weights`] into `out` ([`Model::weight_count`] values),
    /// with `scratch` for the steps between: once `scratch` has held a
    /// pose, nothing is allocated, so an engine's frame need not touch the
    /// heap.
    ///
    /// # Panics
    /// If `out` does not hold one value per weight.
    pub fn weights_into(
        &self,
        skeleton: &Skeleton,
        locals: &[Transform],
        scratch: &mut PoseScratch,
        out: &mut [f32],
    ) {
        assert_eq!(out.len(), self.weight_count(), "one value per weight");
        let PoseScratch {
            world,
            handles,
            angles,
            step,
            ..
        } = scratch;
        match self {
            Self::StaticAverage(_) => out.fill(1.0),
            Self::VertexLinear(layout, m) => {
                layout.params_f64_into(skeleton, locals, angles);
                m.weights_f64_into(angles, step, out);
            }
            Self::VertexClustered(layout, m) => {
                match &m.base {
                    Some(b) => b.joint_angles.params_f64_into(skeleton, locals, angles),
                    None => angles.clear(),
                }
                layout.handles_f64_into(skeleton, locals, world, handles);
                m.weights_with_f64_into(handles, angles, step, out);
            }
        }
        for w in out.iter_mut().filter(|w| !w.is_finite()) {
            *w = 0.0;
        }
    }

    /// AO of every vertex for weights from [`Model::weights`].
    pub fn evaluate_weights(&self, weights: &[f32]) -> Vec<f32> {
        self.form().evaluate(weights)
    }

    /// AO of every vertex in a pose (one local transform per node of
    /// `skeleton`).
    pub fn evaluate(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f32> {
        self.evaluate_weights(&self.weights(skeleton, locals))
    }

    /// Multiply-adds per vertex for these weights: one per non-zero weight
    /// (clusters that MLS leaves out cost nothing), or the mean number of
    /// stored coefficients per vertex for a sparse model.
    pub fn multiply_adds(&self, weights: &[f32]) -> f64 {
        match self.form() {
            FormRef::Sparse(s) => s.multiply_adds(),
            FormRef::Dense(_) => weights.iter().filter(|&&w| w != 0.0).count() as f64,
        }
    }
}

/// The buffers of one pose's step from local transforms to weights
/// ([`Model::weights_into`]; [`crate::method::vertex::VertexAo::evaluate_into`]
/// keeps the weights here too). A player keeps one per character it
/// animates (or per thread); it grows to the model's sizes at the first
/// pose and then allocates nothing.
#[derive(Debug, Clone, Default)]
pub struct PoseScratch {
    /// World transforms of the nodes (the handles are measured in them).
    world: Vec<DAffine3>,
    /// The handle vector.
    handles: Vec<f64>,
    /// The joint angles.
    angles: Vec<f64>,
    /// The per-method steps' buffers.
    step: StepBuffers,
    /// The weights, for an evaluation.
    pub(crate) weights: Vec<f32>,
}

/// The buffers of the methods' per-pose steps ([`VertexLinear`]'s and
/// [`VertexClustered`]'s `_into` functions).
#[derive(Debug, Clone, Default)]
pub(crate) struct StepBuffers {
    /// The clamped angles and their standardised features.
    pub(crate) linear: [Vec<f64>; 2],
    /// The clusters' blend weights.
    pub(crate) omega: Vec<f64>,
    /// The weights before the basis, unrounded.
    pub(crate) unrounded: Vec<f64>,
    /// The basis's sums.
    pub(crate) basis: Vec<f64>,
}
