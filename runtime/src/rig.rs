//! The node hierarchy: rest transforms, parents, and world transforms in a
//! parents-first order. An engine poses it by setting nodes' local
//! transforms (found by name with [`Skeleton::find`]); the nodes it does
//! not set keep their rest transforms ([`Skeleton::rest_locals`]).

use glam::{Affine3A, DAffine3, Mat4, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// A node's local transform as translation, rotation and scale (the form
/// glTF animates).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation in the parent's frame.
    pub translation: Vec3,
    /// Rotation (unit quaternion).
    pub rotation: Quat,
    /// Non-uniform scale.
    pub scale: Vec3,
}

impl Transform {
    /// No translation, no rotation, unit scale.
    pub const IDENTITY: Self = Self {
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };

    /// `parent_from_local` as an affine matrix: T · R · S.
    pub fn to_affine(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }

    /// Decomposes a matrix into T, R, S (glTF requires node matrices to be
    /// decomposable).
    pub fn from_matrix(m: Mat4) -> Self {
        let (scale, rotation, translation) = m.to_scale_rotation_translation();
        Self {
            translation,
            rotation: rotation.normalize(),
            scale,
        }
    }
}

/// One node of the glTF scene graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// The node's name, if the file gives one. Clips shipped in separate
    /// files bind to nodes by this name.
    pub name: Option<String>,
    /// Index of the parent node.
    pub parent: Option<usize>,
    /// The transform of the file: the rest pose.
    pub rest: Transform,
    /// Default morph-target weights of the node's mesh (node weights, else
    /// mesh weights, else zeros); empty without morph targets.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub morph_weights: Vec<f32>,
}

/// The whole node hierarchy of a character.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skeleton {
    /// All nodes of the file, in file order.
    pub nodes: Vec<Node>,
    /// Node indices with every parent before its children.
    pub order: Vec<usize>,
}

impl Skeleton {
    /// World transforms (`world_from_node`) of every node for the given
    /// local transforms, which must have one entry per node.
    pub fn world_from_node(&self, locals: &[Transform]) -> Vec<Affine3A> {
        let mut world = vec![Affine3A::IDENTITY; self.nodes.len()];
        for &i in &self.order {
            let local = locals[i].to_affine();
            world[i] = match self.nodes[i].parent {
                Some(p) => world[p] * local,
                None => local,
            };
        }
        world
    }

    /// [`Skeleton::world_from_node`] in double precision (what the run
    /// time's per-pose step reads).
    pub fn world_from_node_f64(&self, locals: &[Transform]) -> Vec<DAffine3> {
        let mut world = Vec::new();
        self.world_from_node_f64_into(locals, &mut world);
        world
    }

    /// [`Skeleton::world_from_node_f64`] into `world` (cleared first), so
    /// that a player reuses one buffer: nothing is allocated once it has
    /// held a pose.
    pub fn world_from_node_f64_into(&self, locals: &[Transform], world: &mut Vec<DAffine3>) {
        world.clear();
        world.resize(self.nodes.len(), DAffine3::IDENTITY);
        for &i in &self.order {
            let l = &locals[i];
            let local = DAffine3::from_scale_rotation_translation(
                l.scale.as_dvec3(),
                l.rotation.as_dquat(),
                l.translation.as_dvec3(),
            );
            world[i] = match self.nodes[i].parent {
                Some(p) => world[p] * local,
                None => local,
            };
        }
    }

    /// Whether the hierarchy is sound: every parent a node of this
    /// skeleton, and `order` every node once with each parent before its
    /// children. A skeleton read from a file is checked before it is used.
    pub fn check(&self) -> Result<(), String> {
        let n = self.nodes.len();
        let mut seen = vec![false; n];
        if self.order.len() != n {
            return Err(format!(
                "skeleton: {} nodes but {} in order",
                n,
                self.order.len()
            ));
        }
        for &i in &self.order {
            if i >= n || seen[i] {
                return Err(format!("skeleton: node {i} out of range or twice in order"));
            }
            if let Some(p) = self.nodes[i].parent
                && (p >= n || !seen[p])
            {
                return Err(format!(
                    "skeleton: node {i}'s parent {p} does not come before it"
                ));
            }
            seen[i] = true;
        }
        Ok(())
    }

    /// The rest transform of every node: the pose an engine starts from
    /// before it sets the nodes it animates.
    pub fn rest_locals(&self) -> Vec<Transform> {
        self.nodes.iter().map(|n| n.rest).collect()
    }

    /// The first node with this exact name.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.nodes
            .iter()
            .position(|n| n.name.as_deref() == Some(name))
    }

    /// Depth of a node in the hierarchy (0 for roots).
    pub fn depth(&self, mut node: usize) -> usize {
        let mut depth = 0;
        while let Some(p) = self.nodes[node].parent {
            node = p;
            depth += 1;
        }
        depth
    }

    /// Whether `ancestor` is `node` or one of its ancestors.
    pub fn is_ancestor_or_self(&self, ancestor: usize, mut node: usize) -> bool {
        loop {
            if node == ancestor {
                return true;
            }
            match self.nodes[node].parent {
                Some(p) => node = p,
                None => return false,
            }
        }
    }

    /// A readable label for a node: its name, or `node N`.
    pub fn label(&self, node: usize) -> String {
        match &self.nodes[node].name {
            Some(n) if !n.is_empty() => n.clone(),
            _ => format!("node {node}"),
        }
    }
}
