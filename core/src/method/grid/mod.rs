//! Malmer et al.'s AO grids (Malmer, Malmer, Assarsson & Holzschuch 2005;
//! DESIGN §4–5): around each rigid part of an animated object, a 3D grid of
//! the occlusion that part casts into space (and, optionally, the average
//! direction it comes from), so that moving parts shade each other and
//! the ground at run time wherever they are. This room holds:
//!
//! * [`parts`]: the rigid parts of a character (mesh nodes moved by the
//!   animation, or, for skinned characters, the vertices each joint
//!   carries most).
//! * [`field`]: a part's grid box (Eq. 4), the full-sphere occlusion of
//!   its cells (Eq. 5) one z-layer at a time (what a `slab` job computes),
//!   and the finishing steps of §3.3: the boundary rescale, the cells
//!   inside the occluder filled from outside neighbours, the ×2 storage.
//! * [`tclip`]: the `T_clip` table of §5.1 (cone aperture × angle to the
//!   receiver's normal → occlusion, and §5.2.2's blending coefficient).
//! * [`model`]: a baked grid set at run time: the trilinear lookup of each
//!   part's grid through the part's pose, the self-occlusion rule, and the
//!   combination of the parts (1 − Π(1 − aᵢ), or through the cones).
//! * [`base`] and [`static_base`]: aobake's product form, a static base
//!   (per vertex, and a texture on the ground) that the grids' change
//!   rides on, and its fit to ray-traced truth over the training frames.
//! * [`codec`]: the model in the asset container.
//! * [`evaluate`]: ray-traced ground truth of the whole posed object at
//!   its vertices and on the ground, against the grids and the baselines
//!   (DESIGN §6).
//!
//! The jobs (`slab`, and `sample` for the base's frames → `assemble` →
//! `evaluate` → `preview`) are in `bake::grid`.

pub mod evaluate;
pub mod field;
pub mod parts;
pub mod static_base;

/// The run time (the model, the codec, `T_clip`) is the runtime crate's,
/// which engines read grid assets with.
pub use aobake_runtime::method::grid::{ALGORITHM_VERSION, base, codec, gpu, model, tclip};

pub use parts::PartsMode;

use serde::{Deserialize, Serialize};

use crate::trace::MAX_SAMPLES;

/// A grid bake's options (DESIGN §5), with the paper's defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridOptions {
    /// What a part is.
    pub parts: PartsMode,
    /// Cells per grid edge, n (the paper: 32).
    pub resolution: usize,
    /// ε of Eq. 4: occlusion below it is neglected when sizing the grid
    /// (the paper: 0.1, an extent of about 3 r for a cube).
    pub epsilon: f32,
    /// Rays per cell (the paper's ray tracer: 256).
    pub rays: u32,
    /// Hits farther than this (model units) do not occlude, in the grids
    /// and in the ground truth. `None`: how far the largest part's grid
    /// reaches beyond the part by Eq. 4 (max √(A_i / 4πε)), the distance
    /// within which the grids can hold a part's occlusion at all; the
    /// paper's unlimited visibility adds a far field below ε that the
    /// grids drop by design (the evaluation measures it with an explicit
    /// large distance).
    pub max_distance: Option<f32>,
    /// Whether the asset stores the average occluded direction with the
    /// occlusion (RGBA, §5: 4 bytes a cell instead of 1) and the run time
    /// clips each part's cone by the receiver's tangent plane.
    pub cones: bool,
    /// Cells of the `T_clip` table along each of its axes.
    pub tclip_resolution: usize,
    /// aobake's product form: a static base (per vertex, and a texture on
    /// the ground) that the grids' change rides on, fitted to ray-traced
    /// truth over the training frames (`runtime::method::grid::base`).
    /// `false`: the paper's grids alone (still in every report).
    pub static_base: bool,
    /// Texels per side of the base's ground texture.
    pub ground_resolution: usize,
    /// Random clip frames (of the test clips) at which `evaluate` traces
    /// the ground truth.
    pub eval_frames: usize,
    /// Points on the ground plane under the object per evaluation frame.
    pub eval_ground: usize,
    /// Rays per ground-truth point.
    pub eval_rays: u32,
    /// Clip frames (of the training clips) whose mean is the static
    /// average the grids are compared with, and that the static base is
    /// fitted to.
    pub average_frames: usize,
}

impl Default for GridOptions {
    fn default() -> Self {
        Self {
            parts: PartsMode::Rigid,
            resolution: 32,
            epsilon: 0.1,
            rays: 256,
            max_distance: None,
            cones: true,
            tclip_resolution: 32,
            static_base: true,
            ground_resolution: 96,
            eval_frames: 16,
            eval_ground: 1024,
            eval_rays: 256,
            average_frames: 32,
        }
    }
}

impl GridOptions {
    /// Checks every option's range; the error names the option.
    pub fn validate(&self) -> Result<(), String> {
        let o = self;
        if !(2..=128).contains(&o.resolution) {
            return Err(format!(
                "grid.resolution must be between 2 and 128, not {}",
                o.resolution
            ));
        }
        if !(o.epsilon.is_finite() && o.epsilon > 0.0 && o.epsilon < 1.0) {
            return Err("grid.epsilon must be in (0, 1)".into());
        }
        for (name, rays) in [("grid.rays", o.rays), ("grid.eval_rays", o.eval_rays)] {
            if rays == 0 || rays > MAX_SAMPLES {
                return Err(format!(
                    "{name} must be between 1 and {MAX_SAMPLES}, not {rays}"
                ));
            }
        }
        if o.max_distance.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
            return Err("grid.max_distance must be a positive finite number".into());
        }
        if !(2..=256).contains(&o.tclip_resolution) {
            return Err(format!(
                "grid.tclip_resolution must be between 2 and 256, not {}",
                o.tclip_resolution
            ));
        }
        if !(1..=1024).contains(&o.eval_frames) {
            return Err(format!(
                "grid.eval_frames must be between 1 and 1024, not {}",
                o.eval_frames
            ));
        }
        if !(1..=1024).contains(&o.average_frames) {
            return Err(format!(
                "grid.average_frames must be between 1 and 1024, not {}",
                o.average_frames
            ));
        }
        if !(2..=512).contains(&o.ground_resolution) {
            return Err(format!(
                "grid.ground_resolution must be between 2 and 512, not {}",
                o.ground_resolution
            ));
        }
        if o.eval_ground > 1 << 20 {
            return Err("grid.eval_ground must be at most 1048576".into());
        }
        Ok(())
    }

    /// The distance limit of every trace of a bake of `parts` of
    /// `character`: `max_distance`, or the farthest any part's grid
    /// reaches beyond its part by Eq. 4.
    pub fn distance(&self, character: &crate::Character, parts: &[parts::Part]) -> f32 {
        self.max_distance.unwrap_or_else(|| {
            parts
                .iter()
                .map(|p| field::reach(&p.mesh(character).1, self.epsilon))
                .fold(0.0f32, f32::max)
                .max(f32::MIN_POSITIVE)
        })
    }

    /// The tracing parameters of a grid bake's ground truth (its
    /// evaluation and its previews), with the held-out `seed`.
    pub fn truth(&self, distance: f32, seed: u64) -> crate::trace::SurfaceParams {
        crate::trace::SurfaceParams {
            samples: self.eval_rays,
            max_distance: distance,
            seed,
            falloff: crate::trace::Falloff::None,
        }
    }

    /// Cells of one part's grid.
    pub fn cells(&self) -> u64 {
        (self.resolution as u64).pow(3)
    }

    /// Rays a whole bake of `parts` parts over `vertices` vertices traces
    /// (cells, the static base's frames, then the evaluation's, which
    /// takes the base's frames at the vertices from the base instead of
    /// tracing them again, and each vertex's self-occlusion): what the
    /// service bounds, and what the report counts.
    pub fn rays_total(&self, parts: usize, vertices: usize) -> u128 {
        let cells = u128::from(self.cells()) * parts as u128 * u128::from(self.rays);
        let average = self.average_frames as u128;
        let base = u128::from(self.static_base)
            * average
            * (vertices + self.ground_resolution.pow(2)) as u128;
        // The evaluated frames and the noise estimate at the vertices and
        // on the ground; the base's frames on the ground, and at the
        // vertices unless the base traced them.
        let at_vertices =
            (self.eval_frames + 1) as u128 + u128::from(!self.static_base) * average + 1;
        let on_ground = (self.eval_frames + 1) as u128 + average;
        let evaluation = at_vertices * vertices as u128 + on_ground * self.eval_ground as u128;
        cells + (base + evaluation) * u128::from(self.eval_rays)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_papers_and_bad_options_are_named() {
        let o = GridOptions::default();
        o.validate().unwrap();
        assert_eq!((o.resolution, o.epsilon, o.rays), (32, 0.1, 256));
        for (bad, name) in [
            (
                GridOptions {
                    resolution: 1,
                    ..o.clone()
                },
                "grid.resolution",
            ),
            (
                GridOptions {
                    epsilon: f32::NAN,
                    ..o.clone()
                },
                "grid.epsilon",
            ),
            (
                GridOptions {
                    eval_rays: 0,
                    ..o.clone()
                },
                "grid.eval_rays",
            ),
            (
                GridOptions {
                    max_distance: Some(-1.0),
                    ..o.clone()
                },
                "grid.max_distance",
            ),
        ] {
            let e = bad.validate().unwrap_err();
            assert!(e.starts_with(name), "{e}");
        }
        let json = serde_json::to_value(&o).unwrap();
        assert_eq!(serde_json::from_value::<GridOptions>(json).unwrap(), o);
    }
}
