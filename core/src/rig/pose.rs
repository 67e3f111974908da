//! Poses and linear blend skinning.

use glam::{Affine3A, Mat3, Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::{
    geometry::angle_weighted_normals,
    rig::character::Character,
    rig::clip::Clip,
    rig::skeleton::{Skeleton, Transform},
};

/// Local transforms of every node and morph weights of every node: what a
/// clip sampled at a time gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Local transform per node.
    pub locals: Vec<Transform>,
    /// Morph weights per node (empty for nodes without morph targets).
    pub morph_weights: Vec<Vec<f32>>,
}

/// A posed mesh in world space, vertices in the character's order.
#[derive(Debug, Clone, PartialEq)]
pub struct PosedMesh {
    /// World-space positions.
    pub positions: Vec<Vec3>,
    /// World-space unit normals.
    pub normals: Vec<Vec3>,
}

impl Pose {
    /// The transforms written in the file.
    pub fn rest(skeleton: &Skeleton) -> Self {
        Self {
            locals: skeleton.nodes.iter().map(|n| n.rest).collect(),
            morph_weights: skeleton
                .nodes
                .iter()
                .map(|n| n.morph_weights.clone())
                .collect(),
        }
    }

    /// The pose the mesh was modelled in: every skin joint placed where its
    /// inverse bind matrix says (`world_from_joint = bind_from_joint`), so
    /// skinning returns the bind-space vertices. Nodes that are not skin
    /// joints keep their rest transforms; a joint shared by two skins with
    /// different bind matrices follows the first.
    pub fn bind(character: &Character) -> Self {
        let skeleton = &character.skeleton;
        let mut pose = Self::rest(skeleton);
        let mut world = skeleton.world_from_node(&pose.locals);
        let mut bind_world: Vec<Option<Mat4>> = vec![None; skeleton.nodes.len()];
        for range in character.skins.iter().flatten() {
            for joint in &character.joints[range.clone()] {
                bind_world[joint.node].get_or_insert_with(|| joint.joint_from_bind.inverse());
            }
        }
        for &n in &skeleton.order {
            if let Some(target) = bind_world[n] {
                let parent = skeleton.nodes[n]
                    .parent
                    .map_or(Affine3A::IDENTITY, |p| world[p]);
                let local = Mat4::from(parent.inverse()) * target;
                if local.is_finite() {
                    pose.locals[n] = Transform::from_matrix(local);
                }
            }
            let local = pose.locals[n].to_affine();
            world[n] = skeleton.nodes[n].parent.map_or(local, |p| world[p] * local);
        }
        pose
    }

    /// The pose of `clip` at `time` seconds: the rest pose with every
    /// channel of the clip applied.
    pub fn sample(skeleton: &Skeleton, clip: &Clip, time: f32) -> Self {
        let mut pose = Self::rest(skeleton);
        for channel in &clip.channels {
            let node = channel.node;
            channel.apply(time, &mut pose.locals[node], &mut pose.morph_weights[node]);
        }
        pose
    }
}

/// The matrix for normals: the cofactor matrix of the linear part (the
/// inverse transpose times the determinant), which stays right under
/// non-uniform scale and needs no inverse.
fn cofactor(m: &Mat3) -> Mat3 {
    Mat3::from_cols(
        m.y_axis.cross(m.z_axis),
        m.z_axis.cross(m.x_axis),
        m.x_axis.cross(m.y_axis),
    )
}

impl Character {
    /// `world_from_bind` for every palette joint in a pose.
    pub fn joint_matrices(&self, pose: &Pose) -> Vec<Mat4> {
        let world = self.skeleton.world_from_node(&pose.locals);
        self.joints
            .iter()
            .map(|j| Mat4::from(world[j.node]) * j.joint_from_bind)
            .collect()
    }

    /// Linear blend skinning of positions and normals (morph targets first,
    /// at the pose's weights). Normals the file did not have are recomputed
    /// from the posed triangles.
    pub fn skin(&self, pose: &Pose) -> PosedMesh {
        let palette = self.joint_matrices(pose);
        let mut positions = self.positions.clone();
        let mut normals = self.normals.clone();
        for morph in &self.morphs {
            let weights = &pose.morph_weights[morph.node];
            for (target, &w) in morph.targets.iter().zip(weights) {
                if w == 0.0 {
                    continue;
                }
                for (p, d) in positions[morph.vertices.clone()]
                    .iter_mut()
                    .zip(&target.positions)
                {
                    *p += w * *d;
                }
                if let Some(dn) = &target.normals {
                    for (n, d) in normals[morph.vertices.clone()].iter_mut().zip(dn) {
                        *n += w * *d;
                    }
                }
            }
        }
        let k = self.influences;
        for (v, (p, n)) in positions.iter_mut().zip(normals.iter_mut()).enumerate() {
            let mut m = Mat4::ZERO;
            for i in v * k..(v + 1) * k {
                let w = self.joint_weights[i];
                if w != 0.0 {
                    m += palette[self.joint_indices[i] as usize] * w;
                }
            }
            *p = m.transform_point3(*p);
            // The cofactor is det · M⁻ᵀ: a mirroring transform (det < 0)
            // would turn normals inside out without the sign.
            let linear = Mat3::from_mat4(m);
            *n = (cofactor(&linear) * *n * linear.determinant().signum()).normalize_or_zero();
        }
        for prim in self.primitives.iter().filter(|p| p.computed_normals) {
            angle_weighted_normals(
                &positions,
                &self.triangles[prim.triangles.clone()],
                prim.vertices.clone(),
                &mut normals,
            );
        }
        PosedMesh { positions, normals }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cofactor_keeps_normals_perpendicular_under_shear_and_scale() {
        let m = Mat3::from_cols(
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 0.5),
        );
        let tangent = Vec3::new(1.0, 1.0, 0.0);
        let normal = Vec3::new(1.0, -1.0, 0.0);
        let t = m * tangent;
        let n = cofactor(&m) * normal;
        assert!(t.dot(n).abs() < 1e-6);
    }
}
