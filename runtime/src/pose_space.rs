//! A pose as the vectors of numbers the vertex methods read (DESIGN §3),
//! computed from the nodes' local transforms, as an engine has them.
//!
//! * Joint angles (Kontkanen & Aila 2006): for each animated joint, its
//!   local rotation relative to the rest rotation as a rotation vector,
//!   `r = log(rest⁻¹ · q)`, 3 numbers; optionally the translation of the
//!   topmost animated nodes relative to rest, and animated scales. Both
//!   directions are exact up to float rounding: `pose = rest · exp(r)`.
//! * Handles (Kirk & Arikan 2007, Fig. 4): per joint its position and the
//!   position of a point offset from the bone axis, both in the body
//!   root's frame; two handles fix a bone's frame.
//!
//! aobake-core chooses the layouts from the character and its clips when
//! it bakes; an asset stores them in its header.

use glam::{DAffine3, DQuat, DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::rig::{Skeleton, Transform};

/// Closed range of one parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Range {
    /// Smallest value.
    pub min: f32,
    /// Largest value.
    pub max: f32,
}

/// Why a parameterisation could not be made or read.
#[derive(Debug, Clone, thiserror::Error, PartialEq, Eq)]
pub enum ParamError {
    /// No clip rotates a node that moves the mesh.
    #[error("no clip rotates a joint that moves the mesh; joint angles need animated joints")]
    NothingAnimated,
    /// A parameter vector of the wrong length.
    #[error("expected {expected} parameters, got {got}")]
    Length {
        /// Parameters of the layout.
        expected: usize,
        /// Parameters given.
        got: usize,
    },
}

/// The joint-angle parameterisation of a character's poses.
///
/// Rotations of the body root (the joints' lowest common ancestor) and of
/// its ancestors are left out: they turn the whole mesh, which changes no
/// self-occlusion.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointAngles {
    /// Nodes with 3 rotation-vector parameters each, in node order.
    pub joints: Vec<usize>,
    /// Nodes with 3 translation parameters each (offset from rest).
    pub translations: Vec<usize>,
    /// Nodes with 3 scale parameters each: the scale over the rest scale,
    /// minus 1, per axis (linear, not logarithmic: a node scaled to zero is
    /// a plain end of the range, and the geometry moves linearly with it;
    /// absent in layouts written before there were any).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scales: Vec<usize>,
    /// Range per parameter: joints first, then translations, then scales.
    pub ranges: Vec<Range>,
    /// Name per parameter, such as `Hips.rx`, `Root.ty` or `Cube.sx`.
    pub names: Vec<String>,
}

/// `log(q)` as a rotation vector (axis times angle, angle in [0, π]).
pub fn rotation_vector(q: Quat) -> Vec3 {
    rotation_vector_f64(q.as_dquat()).as_vec3()
}

/// [`rotation_vector`] in double precision.
pub fn rotation_vector_f64(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    q.to_scaled_axis()
}

impl JointAngles {
    /// The nodes the parameters move: rotated joints, then translated
    /// nodes, then scaled ones.
    pub fn nodes(&self) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .chain(&self.translations)
            .chain(&self.scales)
            .copied()
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether the layout has no parameters.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Whether the layout fits `skeleton` (every node it names exists, one
    /// range and name per parameter): what a reader checks before it
    /// evaluates a stored layout.
    pub fn check(&self, skeleton: &Skeleton) -> Result<(), String> {
        let params = 3 * (self.joints.len() + self.translations.len() + self.scales.len());
        if self.ranges.len() != params || self.names.len() != params {
            return Err(format!(
                "joint angles: {params} parameters but {} ranges and {} names",
                self.ranges.len(),
                self.names.len()
            ));
        }
        match self.nodes().find(|&n| n >= skeleton.nodes.len()) {
            Some(n) => Err(format!(
                "joint angles: node {n} of {}",
                skeleton.nodes.len()
            )),
            None => Ok(()),
        }
    }

    /// Local transforms → parameters (one transform per node of
    /// `skeleton`), computed in double precision and rounded.
    pub fn params(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f32> {
        self.params_f64(skeleton, locals)
            .into_iter()
            .map(|x| x as f32)
            .collect()
    }

    /// [`JointAngles::params`] unrounded: what the run time computes
    /// weights from. A joint that barely moves has a large inverse
    /// standard deviation, which would make single precision's rounding
    /// visible in the AO.
    pub fn params_f64(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.len());
        self.params_f64_into(skeleton, locals, &mut out);
        out
    }

    /// [`JointAngles::params_f64`] into `out` (cleared first): nothing is
    /// allocated once `out` has held a pose's parameters.
    pub fn params_f64_into(&self, skeleton: &Skeleton, locals: &[Transform], out: &mut Vec<f64>) {
        out.clear();
        for &j in &self.joints {
            let rest = skeleton.nodes[j].rest.rotation.as_dquat();
            let now = locals[j].rotation.as_dquat();
            out.extend(rotation_vector_f64(rest.conjugate() * now).to_array());
        }
        for &t in &self.translations {
            let d =
                locals[t].translation.as_dvec3() - skeleton.nodes[t].rest.translation.as_dvec3();
            out.extend(d.to_array());
        }
        for &t in &self.scales {
            let (now, rest) = (
                locals[t].scale.as_dvec3(),
                skeleton.nodes[t].rest.scale.as_dvec3(),
            );
            out.extend((0..3).map(|a| {
                if rest[a] != 0.0 {
                    now[a] / rest[a] - 1.0
                } else {
                    0.0
                }
            }));
        }
    }

    /// Parameters → local transforms: the rest transforms with the
    /// parameterised rotations, translations and scales set.
    pub fn locals(
        &self,
        skeleton: &Skeleton,
        params: &[f32],
    ) -> Result<Vec<Transform>, ParamError> {
        if params.len() != self.len() {
            return Err(ParamError::Length {
                expected: self.len(),
                got: params.len(),
            });
        }
        let mut locals = skeleton.rest_locals();
        let (rot, rest) = params.split_at(3 * self.joints.len());
        let (trans, scales) = rest.split_at(3 * self.translations.len());
        for (&j, r) in self.joints.iter().zip(rot.chunks_exact(3)) {
            let rest = skeleton.nodes[j].rest.rotation;
            locals[j].rotation = (rest * Quat::from_scaled_axis(Vec3::from_slice(r))).normalize();
        }
        for (&t, d) in self.translations.iter().zip(trans.chunks_exact(3)) {
            locals[t].translation = skeleton.nodes[t].rest.translation + Vec3::from_slice(d);
        }
        for (&t, s) in self.scales.iter().zip(scales.chunks_exact(3)) {
            locals[t].scale = skeleton.nodes[t].rest.scale * (Vec3::ONE + Vec3::from_slice(s));
        }
        Ok(locals)
    }
}

/// Kirk & Arikan's handle layout of a character.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Handles {
    /// The node whose frame the handles are expressed in: the body root
    /// (the joints' lowest common ancestor), so that handles do not change
    /// when the whole character moves or turns; `None` (joints in separate
    /// trees) uses world space.
    pub root: Option<usize>,
    /// Joints with two handles each, in palette order.
    pub joints: Vec<usize>,
    /// Per joint, the off-axis handle in the joint's local frame.
    pub offsets: Vec<Vec3>,
}

impl Handles {
    /// Numbers per pose: 6 per joint.
    pub fn len(&self) -> usize {
        6 * self.joints.len()
    }

    /// Whether there are no handles.
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    /// Whether the layout fits `skeleton`: what a reader checks before it
    /// evaluates a stored layout.
    pub fn check(&self, skeleton: &Skeleton) -> Result<(), String> {
        let nodes = skeleton.nodes.len();
        if self.offsets.len() != self.joints.len() {
            return Err(format!(
                "handles: {} joints but {} offsets",
                self.joints.len(),
                self.offsets.len()
            ));
        }
        match self.joints.iter().chain(&self.root).find(|&&n| n >= nodes) {
            Some(n) => Err(format!("handles: node {n} of {nodes}")),
            None => Ok(()),
        }
    }

    /// [`Handles::handles`] in double precision from the single-precision
    /// transforms: what the run time blends and projects.
    pub fn handles_f64(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.len());
        self.handles_f64_into(skeleton, locals, &mut Vec::new(), &mut out);
        out
    }

    /// [`Handles::handles_f64`] into `out` (cleared first), with `world`
    /// for the nodes' world transforms: nothing is allocated once both
    /// have held a pose.
    pub fn handles_f64_into(
        &self,
        skeleton: &Skeleton,
        locals: &[Transform],
        world: &mut Vec<DAffine3>,
        out: &mut Vec<f64>,
    ) {
        skeleton.world_from_node_f64_into(locals, world);
        let root_from_world = self.root.map_or(DAffine3::IDENTITY, |r| world[r].inverse());
        out.clear();
        for (&j, offset) in self.joints.iter().zip(&self.offsets) {
            let root_from_joint = root_from_world * world[j];
            out.extend(root_from_joint.translation.to_array());
            out.extend(
                root_from_joint
                    .transform_point3(offset.as_dvec3())
                    .to_array(),
            );
        }
    }

    /// The handle vector of a pose (one local transform per node of
    /// `skeleton`): per joint, its position and its off-axis handle, in the
    /// body root's frame.
    /// (Computed in double precision and rounded.)
    pub fn handles(&self, skeleton: &Skeleton, locals: &[Transform]) -> Vec<f32> {
        self.handles_f64(skeleton, locals)
            .into_iter()
            .map(|x| x as f32)
            .collect()
    }
}
