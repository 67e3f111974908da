//! The static base fitted to ray-traced truth (the run time is
//! [`super::base`]): the training frames' mean occlusion at every vertex
//! and ground texel, and the gain of the truth's change on the grids'
//! change over the same frames, one per part and one for the ground.

use glam::{Mat4, Vec3};

use super::{
    base::{GroundSquare, StaticBase},
    evaluate::{Frame, Values},
    model::{GridModel, Terms},
};
use crate::{Character, Clip, method::fit};

/// One training frame: where the receivers are and their traced truth.
#[derive(Debug, Clone)]
pub struct TrainingFrame {
    /// Palette matrices (`world_from_bind`).
    pub palette: Vec<Mat4>,
    /// Posed vertex positions.
    pub positions: Vec<Vec3>,
    /// Posed vertex normals.
    pub normals: Vec<Vec3>,
    /// Traced occlusion at each vertex.
    pub vertices: Vec<f32>,
    /// Traced occlusion at each ground texel's centre.
    pub ground: Vec<f32>,
}

impl TrainingFrame {
    /// The frame posed, with its traced truth.
    pub fn new(
        character: &Character,
        clips: &[Clip],
        frame: &Frame,
        vertices: Vec<f32>,
        ground: Vec<f32>,
    ) -> Self {
        let pose = frame.pose(character, clips);
        let posed = character.skin(&pose);
        Self {
            palette: character.joint_matrices(&pose),
            positions: posed.positions,
            normals: posed.normals,
            vertices,
            ground,
        }
    }
}

/// The box around the character's vertices over `frames` (a unit box
/// when there are none).
pub fn bounds(character: &Character, clips: &[Clip], frames: &[Frame]) -> (Vec3, Vec3) {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for f in frames {
        for p in character.skin(&f.pose(character, clips)).positions {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if lo.is_finite() {
        (lo, hi)
    } else {
        (Vec3::ZERO, Vec3::ONE)
    }
}

/// The ground's centre (x, z) and radius under a box: centred on it, 1.5
/// times as wide as the larger of its x and z sides (the evaluation's
/// ground disc; the base's square is drawn around it).
pub fn ground_disc(lo: Vec3, hi: Vec3) -> (Vec3, f32) {
    let centre = (lo + hi) * 0.5;
    (centre, 1.5 * 0.5 * (hi - lo).x.max((hi - lo).z).max(1e-6))
}

/// The base's ground square under `frames`: around the ground disc of
/// their vertices' box, at their lowest vertex.
pub fn ground_square(
    character: &Character,
    clips: &[Clip],
    frames: &[Frame],
    resolution: usize,
) -> GroundSquare {
    let (lo, hi) = bounds(character, clips, frames);
    let (centre, radius) = ground_disc(lo, hi);
    GroundSquare {
        min: [centre.x - radius, centre.z - radius],
        size: 2.0 * radius,
        height: lo.y,
        resolution,
    }
}

/// The grids' raw occlusion (no base) at a frame's vertices and texels.
fn grids_at(
    model: &GridModel,
    owners: &[Option<usize>],
    texels: &[Vec3],
    frame: &TrainingFrame,
) -> Values {
    let poses = model.poses(&frame.palette);
    let vertices = frame
        .positions
        .iter()
        .zip(&frame.normals)
        .zip(owners)
        .map(|((&p, &n), &own)| model.occlusion(&poses, p, n, own, Terms::All))
        .collect();
    let ground = texels
        .iter()
        .map(|&p| model.occlusion(&poses, p, Vec3::Y, None, Terms::All))
        .collect();
    Values { vertices, ground }
}

/// The base of `model`'s grids (its own base, if any, is ignored) over
/// the training `frames` of a character whose vertices `owners` assigns
/// to parts; offsets rounded to f16 as the asset stores them.
pub fn fit(
    model: &GridModel,
    owners: &[Option<usize>],
    square: GroundSquare,
    frames: &[TrainingFrame],
) -> StaticBase {
    let texels = square.texel_centres();
    let (grid_v, grid_g): (Vec<Vec<f32>>, Vec<Vec<f32>>) = frames
        .iter()
        .map(|f| {
            let g = grids_at(model, owners, &texels, f);
            (g.vertices, g.ground)
        })
        .unzip();
    let truth_v: Vec<Vec<f32>> = frames.iter().map(|f| f.vertices.clone()).collect();
    let truth_g: Vec<Vec<f32>> = frames.iter().map(|f| f.ground.clone()).collect();
    let ground = fit::ground(square, &truth_g, &grid_g);
    let part_gains: Vec<f32> = (0..model.parts.len())
        .map(|k| {
            let mine: Vec<usize> = (0..owners.len())
                .filter(|&i| owners[i] == Some(k))
                .collect();
            fit::gain(&truth_v, &grid_v, &mine)
        })
        .collect();
    let vertex_offsets = fit::offsets(&truth_v, &grid_v, |i| {
        owners[i].map_or(ground.gain, |p| part_gains[p])
    });
    StaticBase {
        vertex_offsets,
        part_gains,
        ground,
    }
}
