//! The rigid parts of a character: what each grid is baked around.
//!
//! A part is one entry of the joint palette (a rigid mesh node, or a skin
//! joint) with the vertices it carries and the triangles among them, in
//! bind space. Its pose is the palette matrix `world_from_bind`, so a
//! grid baked once in bind space follows the part wherever it moves.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::Character;

/// What a part is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PartsMode {
    /// Each mesh node moved by the animation (a rigid object is a one-joint
    /// skin): every vertex must follow one node alone; a skinned vertex is
    /// refused with a pointer to `joints`.
    Rigid,
    /// Each joint's part is the vertices whose largest skin weight is
    /// that joint's (for skinned characters; the parts then bend a little
    /// where they meet).
    Joints,
}

pub use aobake_runtime::method::grid::MAX_PARTS;

/// Weight at or above which a vertex counts as carried by one joint alone.
const RIGID_WEIGHT: f32 = 0.999;

/// One rigid part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Part {
    /// Its name: the node's.
    pub name: String,
    /// The palette entry whose matrix moves it.
    pub joint: usize,
    /// The node of that entry.
    pub node: usize,
    /// Its vertices (indices into the character's).
    pub vertices: Vec<u32>,
    /// Its triangles, as indices into the character's vertices.
    pub triangles: Vec<[u32; 3]>,
}

impl Part {
    /// The part's own mesh: the character's indices of its triangles'
    /// vertices (in joints mode a triangle may reach a vertex of the next
    /// part), their bind-space positions, and the triangles renumbered
    /// into them.
    pub fn mesh(&self, character: &Character) -> (Vec<u32>, Vec<Vec3>, Vec<[u32; 3]>) {
        let mut local = vec![u32::MAX; character.vertex_count()];
        let mut globals = Vec::new();
        let triangles = self
            .triangles
            .iter()
            .map(|t| {
                t.map(|v| {
                    let slot = &mut local[v as usize];
                    if *slot == u32::MAX {
                        *slot = globals.len() as u32;
                        globals.push(v);
                    }
                    *slot
                })
            })
            .collect();
        let positions = globals
            .iter()
            .map(|&v| character.positions[v as usize])
            .collect();
        (globals, positions, triangles)
    }
}

/// Why a character cannot be cut into parts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartsError {
    /// A vertex is skinned across joints in `rigid` mode.
    #[error(
        "vertex {vertex} is skinned across joints (largest weight {weight}), so the character has no rigid parts; bake it with grid.parts = joints"
    )]
    Skinned {
        /// The vertex.
        vertex: usize,
        /// Its largest weight.
        weight: f32,
    },
    /// No part has a triangle.
    #[error("the character has no part with a triangle to cast occlusion")]
    Empty,
    /// Too many parts.
    #[error("the character has {0} parts; a grid bake takes at most {MAX_PARTS}")]
    TooMany(usize),
}

/// The parts of `character`: one per palette entry that carries a vertex
/// and a triangle, in palette order. A triangle belongs to the part of
/// most of its vertices (the first vertex's on a three-way split).
pub fn parts(character: &Character, mode: PartsMode) -> Result<Vec<Part>, PartsError> {
    let k = character.influences;
    let mut owner = Vec::with_capacity(character.vertex_count());
    for v in 0..character.vertex_count() {
        let (mut best, mut weight) = (0u32, f32::NEG_INFINITY);
        for i in v * k..(v + 1) * k {
            if character.joint_weights[i] > weight {
                (best, weight) = (character.joint_indices[i], character.joint_weights[i]);
            }
        }
        if mode == PartsMode::Rigid && weight < RIGID_WEIGHT {
            return Err(PartsError::Skinned { vertex: v, weight });
        }
        owner.push(best as usize);
    }
    let mut parts: Vec<Part> = character
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| Part {
            name: character.skeleton.label(joint.node),
            joint: j,
            node: joint.node,
            vertices: Vec::new(),
            triangles: Vec::new(),
        })
        .collect();
    for (v, &j) in owner.iter().enumerate() {
        parts[j].vertices.push(v as u32);
    }
    for t in &character.triangles {
        let o = t.map(|v| owner[v as usize]);
        let j = if o[1] == o[2] { o[1] } else { o[0] };
        parts[j].triangles.push(*t);
    }
    parts.retain(|p| !p.triangles.is_empty());
    if parts.is_empty() {
        return Err(PartsError::Empty);
    }
    if parts.len() > MAX_PARTS {
        return Err(PartsError::TooMany(parts.len()));
    }
    Ok(parts)
}

/// The part of every vertex of the character (`None`: a vertex of no part,
/// one whose joint carries no triangle).
pub fn owners(parts: &[Part], vertices: usize) -> Vec<Option<usize>> {
    let mut owner = vec![None; vertices];
    for (p, part) in parts.iter().enumerate() {
        for &v in &part.vertices {
            owner[v as usize] = Some(p);
        }
    }
    owner
}

/// [`owners`] as a renderer takes them: each vertex's part index,
/// [`NO_PART`] for none.
pub fn owner_indices(parts: &[Part], vertices: usize) -> Vec<u32> {
    owners(parts, vertices)
        .into_iter()
        .map(|o| o.map_or(NO_PART, |p| p as u32))
        .collect()
}

/// The part index of a vertex of no part (the WGSL's `NO_PART`).
pub const NO_PART: u32 = u32::MAX;
