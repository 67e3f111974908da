//! Kroon's cubemaps (Kroon 2023; DESIGN §5): the occlusion an animated
//! character casts into the space around it over a cyclic clip, stored in
//! nested spheroidal cubemaps. This room grows with the method:
//!
//! * [`geometry`]: the spheroid, its shells and the cube-face texels.
//! * [`field`]: Eq. 3.1 at every texel and shell of a face, one time
//!   sample at a time (what a `face` job computes).
//! * [`discrete`]: the discrete-radial-distance encoding of one texel's
//!   time curve (Algorithm 1, bounded quadratics, 16 bytes).
//! * [`continuous`]: the continuous-radial-distance encoding of one
//!   texel's (time × distance) field (5 × 5 cosine basis and two residual
//!   cubics, 64 bytes over four cubemaps).
//! * [`blurhash`]: Kroon's own layout of the continuous encoding (three
//!   thirds of the cycle as Blurhash channels), evaluated beside it.
//! * [`face`]: one face's raw field (a byte per texel, shell and time
//!   sample), [`face::compute_face`] (the `face` job's loop) and the parts
//!   and manifest its incremental checkpoints are made of.
//! * [`model`]: a baked cubemap at run time: the texel layout an engine
//!   uploads and the CPU lookup (bilinear over texels, linear over shells,
//!   continuous in time).
//!
//! * [`setup`]: what every job of a cubemap bake derives alike from the
//!   inputs: the clip, its time samples, the posed meshes and the spheroid.
//! * [`codec`]: the model in the asset container.
//! * [`evaluate`]: ground truth at random points and on the ground, and
//!   the errors of every encoding against it (DESIGN §6).
//!
//! The jobs themselves (`face` → `assemble` → `evaluate` → `preview`) are
//! in `bake::cubemap`.

pub mod evaluate;
pub mod face;
pub mod field;
pub mod ground;
pub mod model;
pub mod setup;

pub use aobake_runtime::method::cubemap::{
    ALGORITHM_VERSION, blurhash, codec, continuous, discrete, geometry, gpu,
};

use serde::{Deserialize, Serialize};

use crate::trace::{KroonParams, MAX_SAMPLES};

/// The layout of the continuous encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ContinuousLayout {
    /// One 5 × 5 cosine channel over the whole cycle ([`continuous`]).
    Cosine,
    /// Kroon's three thirds of the cycle as Blurhash channels
    /// ([`blurhash`]).
    Thirds,
}

/// A cubemap bake's options (DESIGN §5), with the choices the thesis
/// leaves open.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CubemapOptions {
    /// Texels per face edge (Kroon: 128).
    pub resolution: usize,
    /// Nested shells, `S_d` (Kroon: 8).
    pub shells: usize,
    /// Time samples over the cyclic clip, `S_t` (Kroon: 255, so that a
    /// segment start fits a byte; at most 256).
    pub times: usize,
    /// Outer scaling: the margin around the character (Kroon: "slightly
    /// above 1").
    pub outer: f32,
    /// Inner scaling in [0, 1): pushes the shells outwards, away from the
    /// inside of the mesh (0 is Kroon's reference spacing).
    pub inner: f32,
    /// Rays per sample point. The thesis does not say; 64 keeps the noise
    /// of a point's value (σ ≤ 0.06 before the encodings smooth it) below
    /// what the encodings resolve, at 12.8 G rays for a default bake.
    pub rays: u32,
    /// D_max (model units); `None`: the spheroid's largest radius, so that
    /// a point on the outermost shell still sees the character across it.
    pub max_distance: Option<f32>,
    /// α, the distance falloff (1: linear).
    pub alpha: f32,
    /// w, the strength. A point in space has no normal, so N·D is 1 and
    /// Eq. 3.1 with w = 1 is the falloff-weighted fraction of the full
    /// sphere that the character covers.
    pub weight: f32,
    /// The continuous encoding's weight of too-bright residuals (Kroon:
    /// 0.6).
    pub bright_weight: f32,
    /// Whether the continuous encoding fits its residual curves.
    pub residuals: bool,
    /// The continuous encoding's layout: `cosine` (aobake's one 5 × 5
    /// cosine channel over the whole cycle, f16) or `thirds` (Kroon's: the
    /// cycle in three thirds as the channels of a 5 × 5 Blurhash). Every
    /// report measures both; neither is better everywhere (docs/methods/cubemap.md
    /// gives the figures).
    pub continuous_layout: ContinuousLayout,
    /// The clip to bake (`None`: the first training clip).
    pub clip: Option<String>,
    /// aobake's product form on the ground: a static texture traced on
    /// the ground plane that the cubemap's change rides on there
    /// (`method::cubemap::ground`). `false`: Kroon's cubemap alone
    /// everywhere (still in every report).
    pub static_ground: bool,
    /// Texels per side of the static ground texture.
    pub ground_resolution: usize,
    /// Random clip times at which `evaluate` traces ground truth.
    pub eval_times: usize,
    /// Random points in the spheroid per evaluation time.
    pub eval_points: usize,
    /// Points on the ground plane under the character (the receiver) per
    /// evaluation time.
    pub eval_ground: usize,
    /// Rays per ground-truth point (independent of the bake's rays).
    pub eval_rays: u32,
}

impl Default for CubemapOptions {
    fn default() -> Self {
        Self {
            resolution: 128,
            shells: 8,
            times: 255,
            outer: 1.1,
            inner: 0.25,
            rays: 64,
            max_distance: None,
            alpha: 1.0,
            weight: 1.0,
            bright_weight: 0.6,
            residuals: true,
            continuous_layout: ContinuousLayout::Cosine,
            clip: None,
            static_ground: true,
            ground_resolution: 96,
            eval_times: 16,
            eval_points: 2048,
            eval_ground: 1024,
            eval_rays: 256,
        }
    }
}

impl CubemapOptions {
    /// Checks every option's range; the error names the option.
    pub fn validate(&self) -> Result<(), String> {
        let o = self;
        if !(1..=1024).contains(&o.resolution) {
            return Err(format!(
                "cubemap.resolution must be between 1 and 1024, not {}",
                o.resolution
            ));
        }
        if !(1..=64).contains(&o.shells) {
            return Err(format!(
                "cubemap.shells must be between 1 and 64, not {}",
                o.shells
            ));
        }
        if !(2..=256).contains(&o.times) {
            return Err(format!(
                "cubemap.times must be between 2 and 256 (a segment start is a byte), not {}",
                o.times
            ));
        }
        if !(2..=512).contains(&o.ground_resolution) {
            return Err(format!(
                "cubemap.ground_resolution must be between 2 and 512, not {}",
                o.ground_resolution
            ));
        }
        if !(o.outer.is_finite() && o.outer > 0.0 && o.outer <= 100.0) {
            return Err("cubemap.outer must be in (0, 100]".into());
        }
        if !(o.inner >= 0.0 && o.inner < 1.0) {
            return Err("cubemap.inner must be in [0, 1)".into());
        }
        if o.rays == 0 || o.rays > MAX_SAMPLES {
            return Err(format!(
                "cubemap.rays must be between 1 and {MAX_SAMPLES}, not {}",
                o.rays
            ));
        }
        if o.max_distance.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
            return Err("cubemap.max_distance must be a positive finite number".into());
        }
        if !(o.alpha.is_finite() && o.alpha >= 0.0) {
            return Err("cubemap.alpha must be a finite number ≥ 0".into());
        }
        if !(o.weight.is_finite() && o.weight >= 0.0) {
            return Err("cubemap.weight must be a finite number ≥ 0".into());
        }
        if !(0.0..=1.0).contains(&o.bright_weight) {
            return Err("cubemap.bright_weight must be in [0, 1]".into());
        }
        if !(1..=1024).contains(&o.eval_times) {
            return Err(format!(
                "cubemap.eval_times must be between 1 and 1024, not {}",
                o.eval_times
            ));
        }
        if o.eval_points > 1 << 20 || o.eval_ground > 1 << 20 {
            return Err(
                "cubemap.eval_points and cubemap.eval_ground must be at most 1048576".into(),
            );
        }
        if o.eval_points + o.eval_ground == 0 {
            return Err("cubemap.eval_points and cubemap.eval_ground cannot both be 0".into());
        }
        if o.eval_rays == 0 || o.eval_rays > MAX_SAMPLES {
            return Err(format!(
                "cubemap.eval_rays must be between 1 and {MAX_SAMPLES}, not {}",
                o.eval_rays
            ));
        }
        Ok(())
    }

    /// Eq. 3.1's parameters around `spheroid`, seeded by `seed`.
    pub fn kroon(&self, spheroid: &geometry::Spheroid, seed: u64) -> KroonParams {
        KroonParams {
            samples: self.rays,
            max_distance: self
                .max_distance
                .unwrap_or_else(|| spheroid.radii.max_element()),
            alpha: self.alpha,
            weight: self.weight,
            seed,
        }
    }

    /// Sample points of a whole bake (6 faces × texels × shells × times).
    pub fn points(&self) -> u64 {
        6 * (self.resolution * self.resolution * self.shells * self.times) as u64
    }

    /// Rays a whole bake traces: its sample points, the static ground's
    /// and the evaluation's ground truth (what the service bounds per
    /// request).
    pub fn rays_total(&self) -> u128 {
        let ground = u128::from(self.static_ground)
            * (ground::GROUND_TIMES * self.ground_resolution.pow(2)) as u128;
        (u128::from(self.points()) + ground) * u128::from(self.rays)
            + (self.eval_times * (self.eval_points + self.eval_ground)) as u128
                * u128::from(self.eval_rays)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_kroons_and_bad_options_are_named() {
        let o = CubemapOptions::default();
        o.validate().unwrap();
        assert_eq!(o.points(), 6 * 128 * 128 * 8 * 255);
        for (bad, name) in [
            (
                CubemapOptions {
                    times: 300,
                    ..o.clone()
                },
                "cubemap.times",
            ),
            (
                CubemapOptions {
                    inner: 1.0,
                    ..o.clone()
                },
                "cubemap.inner",
            ),
            (
                CubemapOptions {
                    max_distance: Some(f32::NAN),
                    ..o.clone()
                },
                "cubemap.max_distance",
            ),
            (
                CubemapOptions {
                    rays: 0,
                    ..o.clone()
                },
                "cubemap.rays",
            ),
        ] {
            let e = bad.validate().unwrap_err();
            assert!(e.starts_with(name), "{e}");
        }
        let s = geometry::Spheroid {
            centre: glam::Vec3::ZERO,
            radii: glam::Vec3::new(0.3, 0.9, 0.2),
            outer: 1.1,
            inner: 0.25,
            shells: 8,
        };
        assert_eq!(o.kroon(&s, 5).max_distance, 0.9);
        let json = serde_json::to_value(&o).unwrap();
        let back: CubemapOptions = serde_json::from_value(json).unwrap();
        assert_eq!(back, o);
    }
}
