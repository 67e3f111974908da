//! The character: every mesh of the scene merged into one occluder, bound to
//! a palette of joints.

use std::ops::Range;

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::rig::skeleton::Skeleton;

/// One entry of the joint palette that vertices are bound to: a node and the
/// matrix that takes mesh (bind) space into that node's space. Rigid mesh
/// nodes are one-joint skins with an identity inverse bind matrix.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    /// The node that moves the vertices.
    pub node: usize,
    /// `joint_from_bind`: the skin's inverse bind matrix.
    pub joint_from_bind: Mat4,
}

/// One glTF primitive's share of the merged mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Primitive {
    /// Node that instances the mesh.
    pub node: usize,
    /// Index of the glTF mesh.
    pub mesh: usize,
    /// Index of the primitive within the mesh.
    pub primitive: usize,
    /// The skin, for skinned instances.
    pub skin: Option<usize>,
    /// Its vertices in the merged mesh.
    pub vertices: Range<usize>,
    /// Its triangles in the merged mesh.
    pub triangles: Range<usize>,
    /// The file had no normals: they are computed (angle-weighted) from the
    /// posed triangles every time the mesh is posed.
    pub computed_normals: bool,
}

/// A morph target of one primitive: displacements added with the node's
/// current weight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MorphTarget {
    /// Position displacement per vertex of the primitive.
    pub positions: Vec<Vec3>,
    /// Normal displacement per vertex, when the file gives one.
    pub normals: Option<Vec<Vec3>>,
}

/// The morph targets of one primitive instance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Morph {
    /// The node whose weights drive the targets.
    pub node: usize,
    /// The vertices the targets displace.
    pub vertices: Range<usize>,
    /// The targets, in the order of the node's weights.
    pub targets: Vec<MorphTarget>,
}

/// Counts over the meshes of the file, each mesh counted once: the
/// `unique` numbers of `../shared/data/README.md`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SourceStats {
    /// Meshes in the file.
    pub meshes: usize,
    /// Primitives in the file.
    pub primitives: usize,
    /// Sum of POSITION counts over the file's meshes.
    pub vertices: u64,
    /// Triangles over the file's meshes (points and lines excluded).
    pub triangles: u64,
    /// Skins in the file.
    pub skins: usize,
}

/// An animated character: the merged occluder in bind space, its skeleton
/// and joint palette, and morph targets.
///
/// The product's vertex order is the order here: scene nodes depth-first in
/// child order, each mesh instance's primitives in file order, each
/// primitive's vertices in accessor order.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Character {
    /// Node hierarchy.
    pub skeleton: Skeleton,
    /// Joint palette: skins' joints, then rigid mesh nodes.
    pub joints: Vec<Joint>,
    /// Bind-space positions (mesh space of each instance).
    pub positions: Vec<Vec3>,
    /// Bind-space unit normals.
    pub normals: Vec<Vec3>,
    /// Triangles as vertex indices, counter-clockwise front faces.
    pub triangles: Vec<[u32; 3]>,
    /// The glTF UV sets (`TEXCOORD_k`, k < 4, up to the last some
    /// primitive has): one UV per vertex when every primitive has the set
    /// and it reads, else why not. A texel bake may name one as its atlas.
    #[serde(default)]
    pub uv_sets: Vec<Result<Vec<glam::Vec2>, String>>,
    /// Influences per vertex (a multiple of 4, at least 4).
    pub influences: usize,
    /// Palette index per influence, `influences` per vertex.
    pub joint_indices: Vec<u32>,
    /// Weight per influence, summing to 1 per vertex.
    pub joint_weights: Vec<f32>,
    /// Where each primitive is.
    pub primitives: Vec<Primitive>,
    /// Morph targets, one entry per primitive instance that has them.
    pub morphs: Vec<Morph>,
    /// Skins in the file, with the palette range of each one used.
    pub skins: Vec<Option<Range<usize>>>,
    /// Counts over the file's meshes.
    pub source: SourceStats,
}

impl Character {
    /// Number of vertices of the merged occluder.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Which vertices draw something at these posed `positions`: those
    /// with at least one incident triangle of non-zero area (twice the
    /// area above (10⁻⁶ of the bind pose's bounding-box diagonal)²). A
    /// vertex of a part scaled to zero, or of no triangle, covers no pixel,
    /// and its AO is undefined (its normal is skinned to nothing): the
    /// evaluations leave it out of that pose's errors.
    pub fn drawn_vertices(&self, positions: &[Vec3]) -> Vec<bool> {
        let mut drawn = vec![false; positions.len()];
        for (t, _) in self
            .triangles
            .iter()
            .zip(self.drawn_triangles(positions))
            .filter(|(_, d)| *d)
        {
            for &i in t {
                drawn[i as usize] = true;
            }
        }
        drawn
    }

    /// Which triangles draw something at these posed `positions`: those
    /// of non-zero area (twice the area above (10⁻⁶ of the bind pose's
    /// bounding-box diagonal)²), [`Character::drawn_vertices`]' rule.
    pub fn drawn_triangles(&self, positions: &[Vec3]) -> Vec<bool> {
        let (lo, hi) = crate::geometry::bounds(self.positions.iter().copied())
            .unwrap_or((Vec3::ZERO, Vec3::ZERO));
        let least = (1e-6 * (hi - lo).length()).powi(2);
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                (b - a).cross(c - a).length() > least
            })
            .collect()
    }

    /// Nodes that move vertices (palette nodes), each once, in palette
    /// order.
    pub fn joint_nodes(&self) -> Vec<usize> {
        let mut seen = vec![false; self.skeleton.nodes.len()];
        self.joints
            .iter()
            .filter_map(|j| (!std::mem::replace(&mut seen[j.node], true)).then_some(j.node))
            .collect()
    }

    /// The deepest node that is an ancestor-or-self of every palette node
    /// (their lowest common ancestor), if they share one. Its world
    /// transform, and those of its ancestors, move the whole mesh rigidly:
    /// AO, being self-occlusion, does not depend on them.
    pub fn body_root(&self) -> Option<usize> {
        let chain = |n: usize| {
            let mut c = vec![n];
            while let Some(p) = self.skeleton.nodes[*c.last().expect("non-empty")].parent {
                c.push(p);
            }
            c.reverse();
            c
        };
        let mut joints = self.joint_nodes().into_iter();
        let mut common = chain(joints.next()?);
        for j in joints {
            let other = chain(j);
            let same = common
                .iter()
                .zip(&other)
                .take_while(|(a, b)| a == b)
                .count();
            common.truncate(same);
        }
        common.last().copied()
    }

    /// Nodes whose transform can move a vertex: palette nodes, the nodes of
    /// rigid instances and all their ancestors.
    pub fn relevant_nodes(&self) -> Vec<bool> {
        let mut relevant = vec![false; self.skeleton.nodes.len()];
        for joint in &self.joints {
            let mut node = Some(joint.node);
            while let Some(n) = node {
                if std::mem::replace(&mut relevant[n], true) {
                    break;
                }
                node = self.skeleton.nodes[n].parent;
            }
        }
        relevant
    }

    /// Number of morph targets over all primitives.
    pub fn morph_target_count(&self) -> usize {
        self.morphs.iter().map(|m| m.targets.len()).sum()
    }
}
