//! A vertex asset as an engine plays it: read once, then per frame set the
//! local transforms of the nodes the engine animates (found once by name),
//! compute the pose's weights on the CPU, and evaluate every vertex (on
//! the CPU here, or on the GPU with the weights and the coefficients; see
//! `docs/engines.md`).
//!
//! ```no_run
//! # fn main() -> Result<(), aobake_runtime::AssetError> {
//! use aobake_runtime::method::vertex::{PoseScratch, VertexAo};
//! let bytes = std::fs::read("fox.aobake").expect("the asset");
//! let mut ao = VertexAo::from_bytes(&bytes)?;
//! let head = ao.node("b_Head_05").expect("the rig has the node");
//! // Once per character: the AO buffer and the per-pose step's scratch.
//! let (mut per_vertex, mut scratch) = (vec![0.0; ao.vertices()], PoseScratch::default());
//! // Per frame: set the animated nodes, evaluate (no allocation after the
//! // first frame).
//! let mut local = ao.skeleton().nodes[head].rest;
//! local.rotation = glam::Quat::from_rotation_y(0.3) * local.rotation;
//! ao.set_local(head, local);
//! ao.evaluate_into(&mut scratch, &mut per_vertex);
//! # Ok(()) }
//! ```

use super::{AssetHeader, Model, PoseScratch};
use crate::{
    container::{AssetError, Container},
    rig::{Skeleton, Transform},
};

/// A vertex-method asset (static average, vertex-linear or
/// vertex-clustered) with its rig and the current pose.
#[derive(Debug, Clone)]
pub struct VertexAo {
    model: Model,
    header: AssetHeader,
    skeleton: Skeleton,
    locals: Vec<Transform>,
}

impl VertexAo {
    /// Reads an asset, checking it whole (checksums, lengths, every node
    /// against the rig), and starts at the rest pose. An asset of another
    /// family, or one written before format 1.4 (it has no rig to pose by
    /// node name), is refused with a message.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, AssetError> {
        Self::from_container(&Container::from_bytes(bytes)?)
    }

    /// [`VertexAo::from_bytes`] for a container already read.
    pub fn from_container(container: &Container) -> Result<Self, AssetError> {
        let (model, header) = Model::from_container(container)?;
        Self::new(model, header)
    }

    /// A model and its header, as [`Model::from_container`] reads them.
    pub fn new(model: Model, header: AssetHeader) -> Result<Self, AssetError> {
        let Some(skeleton) = header.rig.clone() else {
            return Err(AssetError::Unsupported(
                "it has no rig (it was written before format 1.4): bake it again to pose it by node name".into(),
            ));
        };
        let locals = skeleton.rest_locals();
        Ok(Self {
            model,
            header,
            skeleton,
            locals,
        })
    }

    /// The fitted model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The asset's header.
    pub fn header(&self) -> &AssetHeader {
        &self.header
    }

    /// The rig: node names, parents and rest transforms.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Vertices, in aobake's vertex order.
    pub fn vertices(&self) -> usize {
        self.model.vertices()
    }

    /// Weights per pose ([`VertexAo::weights`]' length).
    pub fn weight_count(&self) -> usize {
        self.model.weight_count()
    }

    /// The node of this name, to set each frame with
    /// [`VertexAo::set_local`].
    pub fn node(&self, name: &str) -> Option<usize> {
        self.skeleton.find(name)
    }

    /// Sets one node's local transform (translation, rotation, scale in its
    /// parent's frame, as the engine's animation gives it). `false`, and
    /// nothing changed, for a node the rig does not have.
    ///
    /// A rotation that is not of unit length (blended animations drift
    /// off it) is normalised: the handles vertex-clustered reads move with
    /// the matrix a quaternion makes, which a length other than 1 skews.
    /// Unit rotations (within 1e-6 in the squared length) are kept bit for
    /// bit.
    pub fn set_local(&mut self, node: usize, mut local: Transform) -> bool {
        let n2 = local.rotation.length_squared();
        if n2 > 0.0 && n2.is_finite() && (n2 - 1.0).abs() > 1e-6 {
            local.rotation /= n2.sqrt();
        }
        match self.locals.get_mut(node) {
            Some(l) => {
                *l = local;
                true
            }
            None => false,
        }
    }

    /// The local transforms of the pose, one per node.
    pub fn locals(&self) -> &[Transform] {
        &self.locals
    }

    /// Every node back to its rest transform.
    pub fn reset(&mut self) {
        for (local, node) in self.locals.iter_mut().zip(&self.skeleton.nodes) {
            *local = node.rest;
        }
    }

    /// The weights of the current pose, one per coefficient row: what a
    /// GPU evaluation reads (`shaders/wgsl/vertex_ao.wgsl`).
    pub fn weights(&self) -> Vec<f32> {
        self.model.weights(&self.skeleton, &self.locals)
    }

    /// [`VertexAo::weights`] into `out` ([`VertexAo::weight_count`]
    /// values), with `scratch` for the steps between: once `scratch` has
    /// held a pose, nothing is allocated.
    ///
    /// # Panics
    /// If `out` does not hold one value per weight.
    pub fn weights_into(&self, scratch: &mut PoseScratch, out: &mut [f32]) {
        self.model
            .weights_into(&self.skeleton, &self.locals, scratch, out);
    }

    /// The AO of every vertex in the current pose, in [0, 1].
    pub fn evaluate(&self) -> Vec<f32> {
        self.model.evaluate_weights(&self.weights())
    }

    /// [`VertexAo::evaluate`] into `out` ([`VertexAo::vertices`] values),
    /// with `scratch` for the pose's weights and the steps to them: a
    /// player keeps one buffer and one scratch per character, and once the
    /// scratch has held a pose a frame allocates nothing.
    ///
    /// # Panics
    /// If `out` does not hold one value per vertex.
    pub fn evaluate_into(&self, scratch: &mut PoseScratch, out: &mut [f32]) {
        let mut weights = std::mem::take(&mut scratch.weights);
        weights.resize(self.weight_count(), 0.0);
        self.weights_into(scratch, &mut weights);
        self.model.form().evaluate_into(&weights, out);
        scratch.weights = weights;
    }
}
