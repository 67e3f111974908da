//! What `aobake inspect` (and an upload's answer) reports about a
//! character, as data: above `rig` and `pose_space`, which it reads.

use serde::Serialize;

use crate::{
    Character, Clip, Pose,
    geometry::bounds,
    pose_space::{self, LayoutOptions},
};

/// Frame rate at which clips are sampled for the bounds.
const BOUNDS_FPS: f32 = 30.0;
/// At most this many poses per clip for the bounds.
const MAX_BOUNDS_SAMPLES: usize = 2_000;
/// At most this much work for the bounds over all clips, in posed nodes
/// and skinned vertices: about a second on one core. A character of a
/// million vertices gets 200 poses, spread over its clips; past one pose
/// a clip, every second (third, …) clip.
const BOUNDS_BUDGET: usize = 200_000_000;

/// A clip's name and length.
#[derive(Debug, Clone, Serialize)]
pub struct ClipSummary {
    /// Name.
    pub name: String,
    /// Seconds.
    pub duration: f32,
    /// Channels bound to the character.
    pub channels: usize,
    /// Keys over all channels.
    pub keys: usize,
}

/// Counts and bounds of a character with its clips.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Meshes in the file.
    pub meshes: usize,
    /// Primitives in the file.
    pub primitives: usize,
    /// Vertices over the file's meshes, each mesh once.
    pub vertices_unique: u64,
    /// Triangles over the file's meshes, each mesh once.
    pub triangles_unique: u64,
    /// Vertices of the merged occluder (every mesh instance of the scene).
    pub vertices: usize,
    /// Triangles of the merged occluder.
    pub triangles: usize,
    /// Nodes of the scene that instance a mesh.
    pub mesh_instances: usize,
    /// Skins in the file.
    pub skins: usize,
    /// Joints of each skin the scene uses.
    pub skin_joints: Vec<usize>,
    /// Joints in the palette (skin joints used by the scene, plus one per
    /// rigid mesh node).
    pub joints: usize,
    /// Morph targets over all primitives.
    pub morph_targets: usize,
    /// Clips with their durations.
    pub clips: Vec<ClipSummary>,
    /// Joint-angle parameters (3 per animated joint), without root
    /// translation; 0 when no clip rotates a joint.
    pub pose_parameters: usize,
    /// Kirk & Arikan handle numbers (6 per joint).
    pub handle_parameters: usize,
    /// Bounds of the posed mesh over every clip frame (30 fps and every
    /// key), or in the bind pose when there are no clips: `[min, max]`.
    /// (The bind pose is left out otherwise: it may lie far from every
    /// frame, such as a z-up rest pose that the clips stand up.)
    pub bounds: [[f32; 3]; 2],
    /// Length of the bounds' diagonal.
    pub diagonal: f32,
}

impl Summary {
    /// Inspects a character. Skins the mesh at every key and 30 fps frame
    /// of every clip (at most 2,000 per clip) for the bounds, so it costs
    /// about one skinning per frame; a large character with many clips
    /// gets fewer frames (at most 200 million skinned vertices and posed
    /// nodes in all, evenly spread over its clips).
    pub fn of(character: &Character, clips: &[Clip]) -> Self {
        let (stride, per_clip) = bounds_sampling(
            character.vertex_count() + character.skeleton.nodes.len(),
            clips.len(),
        );
        let clip_poses = clips.iter().step_by(stride).flat_map(|clip| {
            clip.sample_times(BOUNDS_FPS, per_clip)
                .into_iter()
                .map(move |t| Pose::sample(&character.skeleton, clip, t))
        });
        let bind = clips.is_empty().then(|| Pose::bind(character));
        let (lo, hi) = bind
            .into_iter()
            .chain(clip_poses)
            .filter_map(|p| bounds(character.skin(&p).positions))
            .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
            .unwrap_or_default();
        let pose_parameters = pose_space::joint_angles(character, clips, LayoutOptions::default())
            .map_or(0, |l| l.len());
        Self {
            meshes: character.source.meshes,
            primitives: character.source.primitives,
            vertices_unique: character.source.vertices,
            triangles_unique: character.source.triangles,
            vertices: character.vertex_count(),
            triangles: character.triangles.len(),
            mesh_instances: {
                let mut nodes: Vec<usize> = character.primitives.iter().map(|p| p.node).collect();
                nodes.dedup();
                nodes.len()
            },
            skins: character.source.skins,
            skin_joints: character.skins.iter().flatten().map(|r| r.len()).collect(),
            joints: character.joints.len(),
            morph_targets: character.morph_target_count(),
            clips: clips
                .iter()
                .map(|c| ClipSummary {
                    name: c.name.clone(),
                    duration: c.duration,
                    channels: c.channels.len(),
                    keys: c.channels.iter().map(|ch| ch.keys()).sum(),
                })
                .collect(),
            pose_parameters,
            handle_parameters: pose_space::handles(character).len(),
            bounds: [lo.to_array(), hi.to_array()],
            diagonal: (hi - lo).length(),
        }
    }
}

/// Which clips (every `stride`-th) and how many poses of each the bounds
/// sample, for poses that each cost `per_pose`: within [`BOUNDS_BUDGET`]
/// in all, never more than [`MAX_BOUNDS_SAMPLES`] a clip.
fn bounds_sampling(per_pose: usize, clips: usize) -> (usize, usize) {
    let poses = (BOUNDS_BUDGET / per_pose.max(1)).max(1);
    let stride = clips.div_ceil(poses).max(1);
    let sampled = clips.div_ceil(stride).max(1);
    (stride, (poses / sampled).clamp(1, MAX_BOUNDS_SAMPLES))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bounds_stay_within_their_budget() {
        // Small characters keep every frame of every clip (up to 2,000).
        assert_eq!(bounds_sampling(3_000, 32), (1, MAX_BOUNDS_SAMPLES));
        // A million vertices: 200 poses over 10 clips.
        assert_eq!(bounds_sampling(1_000_000, 10), (1, 20));
        // 4,096 clips of a tiny mesh: every frame still fits.
        assert_eq!(bounds_sampling(10, 4_096), (1, MAX_BOUNDS_SAMPLES));
        for (per_pose, clips) in [
            (4_000_000, 4_096),
            (1, 1),
            (10, 4_096),
            (50_000, 9_999),
            (7_214, 14),
        ] {
            let (stride, per_clip) = bounds_sampling(per_pose, clips);
            let poses = clips.div_ceil(stride) * per_clip;
            assert!(
                poses * per_pose <= BOUNDS_BUDGET.max(per_pose),
                "{per_pose} × {clips}: {poses} poses"
            );
            assert!((1..=MAX_BOUNDS_SAMPLES).contains(&per_clip));
        }
    }
}
