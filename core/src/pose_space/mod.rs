//! Poses as vectors of numbers (DESIGN §3): choosing the layouts from a
//! character and its clips, and seeded samplers of reference poses. The
//! layouts themselves, and the step from a pose to its numbers, are in
//! the runtime (`aobake_runtime::pose_space`), which engines use too.
//!
//! * Joint angles (Kontkanen & Aila 2006): for each animated joint, its
//!   local rotation relative to the rest rotation as a rotation vector,
//!   `r = log(rest⁻¹ · q)`, 3 numbers; optionally the translation of the
//!   topmost animated nodes relative to rest. Both directions are exact up
//!   to float rounding: `pose = rest · exp(r)`.
//! * Handles (Kirk & Arikan 2007, Fig. 4): per joint its position and the
//!   position of a point offset from the bone axis, both relative to the
//!   root joint's position; two handles fix a bone's frame.

pub use aobake_runtime::pose_space::{Handles, JointAngles, ParamError, Range, rotation_vector};
use glam::Vec3;
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::{
    geometry::bounds,
    rig::character::Character,
    rig::clip::{Clip, Property},
    rig::pose::Pose,
    rig::skeleton::Skeleton,
};

/// At most this many poses per clip when finding parameter ranges.
const MAX_RANGE_SAMPLES: usize = 10_000;

/// How a joint-angle layout is derived from clips.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LayoutOptions {
    /// Add the translation of the topmost animated nodes below the body
    /// root (3 numbers each): parts that slide against the rest of the
    /// mesh (the body root's own translation moves the whole mesh and
    /// changes no AO, so it is never a parameter).
    pub root_translation: bool,
    /// Animated scales of nodes that move the mesh are parameters too.
    pub scales: bool,
    /// Widen each range by this fraction of its span on both sides.
    pub margin: f32,
    /// Frame rate at which clips are sampled to find the ranges, besides
    /// every key time (cubic splines can overshoot their keys).
    pub fps: f32,
}

impl Default for LayoutOptions {
    fn default() -> Self {
        Self {
            root_translation: true,
            scales: true,
            margin: 0.1,
            fps: 30.0,
        }
    }
}

/// The joint-angle layout for the joints that `clips` rotate, with ranges
/// over the clips' frames widened by the margin.
pub fn joint_angles(
    character: &Character,
    clips: &[Clip],
    options: LayoutOptions,
) -> Result<JointAngles, ParamError> {
    let skeleton = &character.skeleton;
    let relevant = character.relevant_nodes();
    // The body root and its ancestors move the mesh rigidly; AO does
    // not depend on their rotations.
    let mut rigid = vec![false; skeleton.nodes.len()];
    let mut n = character.body_root();
    while let Some(r) = n {
        rigid[r] = true;
        n = skeleton.nodes[r].parent;
    }
    let animated = |property: Property| {
        let mut nodes: Vec<usize> = clips
            .iter()
            .flat_map(|c| &c.channels)
            .filter(|c| {
                c.property == property
                    && relevant[c.node]
                    && (property != Property::Rotation || !rigid[c.node])
            })
            .map(|c| c.node)
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes
    };
    let joints = animated(Property::Rotation);
    if joints.is_empty() {
        return Err(ParamError::NothingAnimated);
    }
    let translations = if options.root_translation {
        let moved: Vec<usize> = animated(Property::Translation)
            .into_iter()
            .filter(|&n| !rigid[n])
            .collect();
        let mut is_animated = vec![false; skeleton.nodes.len()];
        for &n in joints.iter().chain(&moved) {
            is_animated[n] = true;
        }
        moved
            .into_iter()
            .filter(|&n| {
                let mut p = skeleton.nodes[n].parent;
                while let Some(a) = p {
                    if is_animated[a] {
                        return false;
                    }
                    p = skeleton.nodes[a].parent;
                }
                true
            })
            .collect()
    } else {
        Vec::new()
    };
    // A scaled node (grown, squashed, shrunk to nothing) moves geometry
    // the rotations and translations do not describe.
    let scales: Vec<usize> = if options.scales {
        animated(Property::Scale)
            .into_iter()
            .filter(|&n| !rigid[n])
            .collect()
    } else {
        Vec::new()
    };
    let mut names = Vec::new();
    for &j in &joints {
        for axis in ["rx", "ry", "rz"] {
            names.push(format!("{}.{axis}", skeleton.label(j)));
        }
    }
    for &t in &translations {
        for axis in ["tx", "ty", "tz"] {
            names.push(format!("{}.{axis}", skeleton.label(t)));
        }
    }
    for &t in &scales {
        for axis in ["sx", "sy", "sz"] {
            names.push(format!("{}.{axis}", skeleton.label(t)));
        }
    }
    let mut layout = JointAngles {
        ranges: vec![
            Range {
                min: f32::INFINITY,
                max: f32::NEG_INFINITY,
            };
            names.len()
        ],
        joints,
        translations,
        scales,
        names,
    };
    for clip in clips {
        for t in clip.sample_times(options.fps, MAX_RANGE_SAMPLES) {
            let params = layout.params(skeleton, &Pose::sample(skeleton, clip, t).locals);
            for (range, v) in layout.ranges.iter_mut().zip(params) {
                range.min = range.min.min(v);
                range.max = range.max.max(v);
            }
        }
    }
    // A translation or scale channel that never moves its node (many
    // exporters key every bone's rest offset and scale) carries
    // nothing: left out.
    let r = layout.joints.len() * 3;
    let t = layout.translations.len();
    let moving: Vec<bool> = (0..t + layout.scales.len())
        .map(|k| {
            layout.ranges[r + 3 * k..r + 3 * k + 3]
                .iter()
                .any(|x| x.max - x.min > 1e-6 * x.max.abs().max(x.min.abs()).max(1.0))
        })
        .collect();
    if moving.iter().any(|m| !m) {
        let keep = |i: usize| i < r || moving[(i - r) / 3];
        let mut i = 0;
        layout.names.retain(|_| {
            i += 1;
            keep(i - 1)
        });
        let mut i = 0;
        layout.ranges.retain(|_| {
            i += 1;
            keep(i - 1)
        });
        let mut k = 0;
        layout.translations.retain(|_| {
            k += 1;
            moving[k - 1]
        });
        layout.scales.retain(|_| {
            k += 1;
            moving[k - 1]
        });
    }
    let first_scale = r + 3 * layout.translations.len();
    for (i, range) in layout.ranges.iter_mut().enumerate() {
        let pad = (range.max - range.min) * options.margin;
        // The margin does not take a scale through zero (parameter
        // −1) that the clips never took there: a node turned inside
        // out is no pose of the character.
        let floor = if i >= first_scale && range.min >= -1.0 {
            -1.0
        } else {
            f32::NEG_INFINITY
        };
        range.min = (range.min - pad).max(floor);
        range.max += pad;
    }
    Ok(layout)
}

/// For every vertex of `character`, the parameters of `layout` that can move
/// geometry near it (in increasing order): those of the nodes that skin
/// it and of their parents and children on the skeleton (the joints
/// next to a vertex's bones are where the occluders that move relative
/// to it hang).
pub fn local_parameters(layout: &JointAngles, character: &Character) -> Vec<Vec<usize>> {
    let skeleton = &character.skeleton;
    let nodes = skeleton.nodes.len();
    // Parameters of each node.
    let mut of_node: Vec<Vec<usize>> = vec![Vec::new(); nodes];
    for (k, &j) in layout.joints.iter().enumerate() {
        of_node[j].extend(3 * k..3 * k + 3);
    }
    let r = 3 * layout.joints.len();
    for (k, &t) in layout.translations.iter().chain(&layout.scales).enumerate() {
        of_node[t].extend(r + 3 * k..r + 3 * k + 3);
    }
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); nodes];
    for (n, node) in skeleton.nodes.iter().enumerate() {
        if let Some(p) = node.parent {
            children[p].push(n);
        }
    }
    let k = character.influences;
    (0..character.vertex_count())
        .map(|v| {
            let mut params = Vec::new();
            for i in v * k..(v + 1) * k {
                if character.joint_weights[i] <= 0.0 {
                    continue;
                }
                let node = character.joints[character.joint_indices[i] as usize].node;
                let ring = std::iter::once(node)
                    .chain(skeleton.nodes[node].parent)
                    .chain(children[node].iter().copied());
                for n in ring {
                    params.extend(&of_node[n]);
                }
            }
            params.sort_unstable();
            params.dedup();
            params
        })
        .collect()
}

/// Parameters → pose: the rest pose with the parameterised rotations,
/// translations and scales set.
pub fn pose(layout: &JointAngles, skeleton: &Skeleton, params: &[f32]) -> Result<Pose, ParamError> {
    let mut pose = Pose::rest(skeleton);
    pose.locals = layout.locals(skeleton, params)?;
    Ok(pose)
}

/// Moves every parameter of `params` by a uniform offset of up to
/// ±`fraction` of its range, clamped to the range.
pub fn perturb(layout: &JointAngles, params: &mut [f32], fraction: f32, rng: &mut ChaCha8Rng) {
    for (v, r) in params.iter_mut().zip(&layout.ranges) {
        let reach = fraction * (r.max - r.min);
        // Drawn for every parameter, so that a pose's offsets do not
        // depend on which ranges are empty.
        let u: f32 = rng.random_range(-1.0..=1.0);
        if reach > 0.0 && reach.is_finite() {
            *v = (*v + u * reach).clamp(r.min, r.max);
        }
    }
}

/// `count` parameter vectors, each parameter uniform in its range
/// (Kontkanen & Aila's random reference poses). Same seed, same poses.
pub fn sample_uniform(layout: &JointAngles, count: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            layout
                .ranges
                .iter()
                .map(|r| {
                    if r.max > r.min && (r.max - r.min).is_finite() {
                        rng.random_range(r.min..=r.max)
                    } else {
                        r.min
                    }
                })
                .collect()
        })
        .collect()
}

/// A clip and a time in it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClipFrame {
    /// Index into the clip list.
    pub clip: usize,
    /// Seconds.
    pub time: f32,
}

/// Every frame of every clip at `fps` (Kirk & Arikan train on clip frames).
pub fn clip_frames(clips: &[Clip], fps: f32) -> Vec<ClipFrame> {
    clips
        .iter()
        .enumerate()
        .flat_map(|(clip, c)| {
            c.frame_times(fps)
                .into_iter()
                .map(move |time| ClipFrame { clip, time })
        })
        .collect()
}

/// `count` frames drawn uniformly over the total duration of the clips,
/// seeded. Clips of zero duration contribute their single frame with the
/// weight of one 30 fps frame.
pub fn random_clip_frames(clips: &[Clip], count: usize, seed: u64) -> Vec<ClipFrame> {
    let spans: Vec<f32> = clips.iter().map(|c| c.duration.max(1.0 / 30.0)).collect();
    let total: f32 = spans.iter().sum();
    if clips.is_empty() || total <= 0.0 {
        return Vec::new();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let mut u = rng.random_range(0.0..total);
            let mut clip = 0;
            while clip + 1 < spans.len() && u >= spans[clip] {
                u -= spans[clip];
                clip += 1;
            }
            ClipFrame {
                clip,
                time: u.min(clips[clip].duration),
            }
        })
        .collect()
}

/// Kirk & Arikan's handles for `character`: one off-axis handle per joint,
/// perpendicular to the bone (to the first child joint, else from the
/// parent joint) at half the bone's length, measured in the rest pose.
pub fn handles(character: &Character) -> Handles {
    let skeleton = &character.skeleton;
    let joints = character.joint_nodes();
    let world = skeleton.world_from_node(&Pose::rest(skeleton).locals);
    let root = character.body_root();
    let diag =
        bounds(character.positions.iter().copied()).map_or(1.0, |(lo, hi)| (hi - lo).length());
    let is_joint = {
        let mut v = vec![false; skeleton.nodes.len()];
        joints.iter().for_each(|&j| v[j] = true);
        v
    };
    // Nearest joint ancestor of each joint, found once (depth-bounded).
    let parents: Vec<Option<usize>> = joints
        .iter()
        .map(|&j| {
            let mut n = j;
            while let Some(p) = skeleton.nodes[n].parent {
                if is_joint[p] {
                    return Some(p);
                }
                n = p;
            }
            None
        })
        .collect();
    let offsets = joints
        .iter()
        .zip(&parents)
        .map(|(&j, &parent)| {
            let here = world[j].translation;
            let child = joints
                .iter()
                .zip(&parents)
                .find(|(_, p)| **p == Some(j))
                .map(|(c, _)| c);
            let bone = match (child, parent) {
                (Some(&c), _) => Vec3::from(world[c].translation - here),
                (None, Some(p)) => Vec3::from(here - world[p].translation),
                (None, None) => Vec3::ZERO,
            };
            let (dir, len) = match bone.try_normalize() {
                Some(d) => (d, bone.length()),
                None => (Vec3::Y, 0.1 * diag),
            };
            let offset_in_world = dir.any_orthonormal_vector() * (0.5 * len);
            world[j].inverse().transform_vector3(offset_in_world)
        })
        .collect();
    Handles {
        root,
        joints,
        offsets,
    }
}
