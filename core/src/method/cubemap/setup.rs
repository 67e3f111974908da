//! What every job of a cubemap bake derives alike from its inputs: the
//! clip, its `S_t` time samples over the cycle, the posed mesh at each, and
//! the spheroid around them. Every `face` job, `assemble`, `evaluate` and
//! `preview` computes this again from the same inputs and gets the same
//! numbers, so nothing of it travels between jobs.

use glam::Vec3;

use crate::{Character, Clip, rig::pose::Pose};

use super::{
    CubemapOptions,
    face::FaceSampling,
    geometry::Spheroid,
    model::{CubemapLayout, Encoding},
};

/// Most key times the spheroid looks at besides the time samples.
const MAX_KEY_TIMES: usize = 1024;

/// A cubemap bake's clip, time samples and spheroid.
#[derive(Debug, Clone)]
pub struct Setup<'a> {
    /// The character.
    pub character: &'a Character,
    /// The baked clip.
    pub clip: &'a Clip,
    /// The options.
    pub options: CubemapOptions,
    /// Time sample `m` is clip time `times[m] = m · duration / S_t`: the
    /// cycle's end is its start, so it is not sampled twice.
    pub times: Vec<f32>,
    /// The spheroid around every time sample and key frame.
    pub spheroid: Spheroid,
    /// The lowest vertex height over those frames: where the ground plane
    /// (the receiver the evaluation and previews use) is.
    ground_y: f32,
}

impl<'a> Setup<'a> {
    /// Poses the clip at every time sample and key time and fits the
    /// spheroid around them.
    pub fn new(character: &'a Character, clip: &'a Clip, options: &CubemapOptions) -> Self {
        let times: Vec<f32> = (0..options.times)
            .map(|m| m as f32 * clip.duration / options.times as f32)
            .collect();
        let mut all = times.clone();
        let keys = clip.key_times();
        let step = keys.len().div_ceil(MAX_KEY_TIMES).max(1);
        all.extend(keys.into_iter().step_by(step));
        let frames: Vec<Vec<Vec3>> = all
            .iter()
            .map(|&t| positions_at(character, clip, t))
            .collect();
        let spheroid = Spheroid::around(
            frames.iter().map(Vec::as_slice),
            options.outer,
            options.inner,
            options.shells,
        );
        let ground_y = frames
            .iter()
            .flatten()
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min);
        Self {
            character,
            clip,
            options: options.clone(),
            times,
            spheroid,
            ground_y: if ground_y.is_finite() {
                ground_y
            } else {
                spheroid.centre.y
            },
        }
    }

    /// The height of the ground plane: the lowest vertex over the clip.
    pub fn ground_y(&self) -> f32 {
        self.ground_y
    }

    /// The half axes (x, z) of the ellipse where the ground plane cuts the
    /// outer spheroid: the ground's footprint the evaluation samples and
    /// the static ground covers.
    pub fn ground_section(&self) -> (f32, f32) {
        let s = &self.spheroid;
        let scale = s.radii * s.outer;
        let h = ((self.ground_y - s.centre.y) / scale.y).clamp(-1.0, 1.0);
        let section = (1.0 - h * h).max(0.0).sqrt();
        (scale.x * section, scale.z * section)
    }

    /// The posed mesh's positions at time sample `m`.
    pub fn positions(&self, m: usize) -> Vec<Vec3> {
        positions_at(self.character, self.clip, self.times[m])
    }

    /// The posed mesh's positions at clip time `t`.
    pub fn positions_at(&self, t: f32) -> Vec<Vec3> {
        positions_at(self.character, self.clip, t)
    }

    /// What a face's sampling needs, seeded by the bake's seed.
    pub fn sampling(&self, seed: u64) -> FaceSampling {
        FaceSampling {
            spheroid: self.spheroid,
            resolution: self.options.resolution,
            kroon: self.options.kroon(&self.spheroid, seed),
        }
    }

    /// The layout of the baked cubemap in `encoding`.
    pub fn layout(&self, encoding: Encoding) -> CubemapLayout {
        CubemapLayout {
            spheroid: self.spheroid,
            resolution: self.options.resolution,
            times: self.options.times,
            encoding,
            duration: self.clip.duration,
        }
    }

    /// The shape of a face field: (resolution, shells, times).
    pub fn shape(&self) -> (usize, usize, usize) {
        (
            self.options.resolution,
            self.options.shells,
            self.options.times,
        )
    }
}

fn positions_at(character: &Character, clip: &Clip, t: f32) -> Vec<Vec3> {
    character
        .skin(&Pose::sample(&character.skeleton, clip, t))
        .positions
}
