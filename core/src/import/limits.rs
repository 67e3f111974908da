//! Limits on untrusted input, checked against the counts a file declares
//! before anything is allocated for them.

use serde::{Deserialize, Serialize};

/// Upper bounds for one import. Every count is checked against the numbers
/// the glTF JSON declares, before the data is decoded, so a file that claims
/// a billion vertices is rejected without allocating for them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Limits {
    /// Bytes of the main file plus every side file.
    pub max_file_bytes: u64,
    /// Vertices of the merged occluder, counted per mesh instance.
    pub max_vertices: u64,
    /// Triangles of the merged occluder, counted per mesh instance.
    pub max_triangles: u64,
    /// Nodes in the glTF scene graph.
    pub max_nodes: u64,
    /// Joints over all skins used by the scene, rigid mesh nodes included.
    pub max_joints: u64,
    /// Keyframes over every animation sampler of the file.
    pub max_keyframes: u64,
    /// Largest key time in seconds (clips are sampled frame by frame).
    pub max_clip_seconds: f32,
    /// Morph targets of one mesh.
    pub max_morph_targets: u64,
    /// Morph-target data: vertices × targets over all primitives.
    pub max_morph_deltas: u64,
    /// Nesting depth of JSON arrays and objects.
    pub max_json_depth: usize,
    /// Values in the JSON (numbers, strings, arrays, objects, …): parsing
    /// builds a tree that costs tens of bytes a value, so a body of
    /// `[0,0,0,…]` is refused before it is parsed.
    pub max_json_values: u64,
    /// Animations in one file.
    pub max_animations: u64,
    /// Numbers (components) decoded from accessors without a bufferView,
    /// over the file: zeros the file does not carry (sparse morph targets
    /// rest on them), so a few bytes of JSON could otherwise declare
    /// gigabytes of them.
    pub max_zero_filled: u64,
}

impl Limits {
    /// Limits that admit any production character a studio would bake on one
    /// machine (a few million vertices, a thousand joints), and nothing that
    /// could exhaust memory.
    pub const fn production() -> Self {
        Self {
            max_file_bytes: 512 << 20,
            max_vertices: 4_000_000,
            max_triangles: 8_000_000,
            max_nodes: 100_000,
            max_joints: 2_048,
            max_keyframes: 20_000_000,
            max_clip_seconds: 3600.0,
            max_morph_targets: 256,
            max_morph_deltas: 16_000_000,
            max_json_depth: 64,
            max_json_values: 8_000_000,
            max_animations: 4_096,
            max_zero_filled: 64_000_000,
        }
    }
}

impl Default for Limits {
    fn default() -> Self {
        Self::production()
    }
}
