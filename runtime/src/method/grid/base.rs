//! The static base the grids' change rides on: aobake's product form of
//! the grid method (issue 29), beside the paper's grids alone.
//!
//! Malmer et al.'s grids shade a part's own vertices by a rule of thumb
//! (§4.2's `(ao_grid − 1)/2`, or its cone) and keep only the near field on
//! the ground, so a static bake beats them where the character is. The
//! base keeps what a static bake gets right and lets the grids say only
//! what a pose changes. For a receiver `r` whose grids give `g(r)` at a
//! frame:
//!
//! ```text
//! ao(r) = clamp(k · g(r) + offset(r), 0, 1)
//! offset(r) = static(r) − k · mean(g(r))
//! ```
//!
//! where `static(r)` is the mean ray-traced occlusion over the training
//! frames, `mean(g(r))` the grids' mean over the same frames, and `k` the
//! least-squares gain of the truth's change on the grids' change over
//! those frames (one per part for its vertices, one for the ground):
//! where the grids' change tracks the truth `k` is near 1, where it is
//! noise `k` falls towards 0 and the base stays static.
//!
//! The offsets are per vertex of the character and, for the ground, a
//! square texture on the ground plane of the clips' space (bilinear
//! between texel centres, clamped to the edge texels inside the square;
//! outside it the offset is 0).

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// The ground texture's placement: a square on the plane `y = height` of
/// the clips' space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GroundSquare {
    /// The square's corner at its smallest x and z.
    pub min: [f32; 2],
    /// Its side.
    pub size: f32,
    /// The plane's height (the lowest vertex over the training frames).
    pub height: f32,
    /// Texels per side.
    pub resolution: usize,
}

impl GroundSquare {
    /// The centre of texel (x, z): texel `x + z·resolution`.
    pub fn texel_centre(&self, x: usize, z: usize) -> Vec3 {
        let step = self.size / self.resolution as f32;
        Vec3::new(
            self.min[0] + (x as f32 + 0.5) * step,
            self.height,
            self.min[1] + (z as f32 + 0.5) * step,
        )
    }

    /// Every texel's centre, x fastest.
    pub fn texel_centres(&self) -> Vec<Vec3> {
        let n = self.resolution;
        (0..n * n)
            .map(|i| self.texel_centre(i % n, i / n))
            .collect()
    }

    /// Texels.
    pub fn texels(&self) -> usize {
        self.resolution * self.resolution
    }

    /// `p` in texture space ([0, 1]² is the square), from its x and z.
    pub fn uv(&self, p: Vec3) -> Vec2 {
        (Vec2::new(p.x, p.z) - Vec2::from(self.min)) / self.size
    }
}

/// The ground's base.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundBase {
    /// Where the texture lies.
    pub square: GroundSquare,
    /// The gain of the grids' change on the ground.
    pub gain: f32,
    /// Per texel (x fastest), the offset (f16 values).
    pub offsets: Vec<f32>,
}

impl GroundBase {
    /// The offset at ground point `p`: bilinear between texel centres
    /// (clamped to the edge texels) inside the square, 0 outside.
    pub fn offset(&self, p: Vec3) -> f32 {
        let uv = self.square.uv(p);
        if uv.cmplt(Vec2::ZERO).any() || uv.cmpgt(Vec2::ONE).any() {
            return 0.0;
        }
        let n = self.square.resolution;
        let last = (n - 1) as f32;
        let s = (uv * n as f32 - 0.5).clamp(Vec2::ZERO, Vec2::splat(last));
        let i0 = s.floor().min(Vec2::splat((last - 1.0).max(0.0)));
        let f = s - i0;
        let (x, z) = (i0.x as usize, i0.y as usize);
        let (x1, z1) = ((x + 1).min(n - 1), (z + 1).min(n - 1));
        let at = |x: usize, z: usize| self.offsets[z * n + x];
        let near = at(x, z) + (at(x1, z) - at(x, z)) * f.x;
        let far = at(x, z1) + (at(x1, z1) - at(x, z1)) * f.x;
        near + (far - near) * f.y
    }
}

/// The static base of a grid asset.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticBase {
    /// Per vertex of the character, the offset (f16 values).
    pub vertex_offsets: Vec<f32>,
    /// Per part, the gain of the grids' change at its vertices (receivers
    /// of no part take the ground's).
    pub part_gains: Vec<f32>,
    /// The ground.
    pub ground: GroundBase,
}

/// Where a receiver is, for [`super::model::GridModel::ao`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Receiver {
    /// The character's vertex `index`, carried by `part` (`None`: by no
    /// part).
    Vertex {
        /// Its index in the character.
        index: usize,
        /// Its part.
        part: Option<usize>,
    },
    /// A point of the ground plane (normal up).
    Ground,
    /// Any other surface point, on no part: the ground's gain, no
    /// offset.
    Other,
}

impl Receiver {
    /// Vertex `index` whose part is `owner` in the word form the GPU
    /// lookups use (`u32::MAX`: no part).
    pub fn vertex(index: usize, owner: u32) -> Self {
        Self::Vertex {
            index,
            part: (owner != u32::MAX).then_some(owner as usize),
        }
    }
}

impl StaticBase {
    /// The gain and offset of a receiver at `p`.
    ///
    /// The GPU lookups (`grid_ao` in `shaders/wgsl/common/grid_lookup.wgsl`)
    /// take the offset from the caller, [`Self::offset`].
    pub fn terms(&self, receiver: Receiver, p: Vec3) -> (f32, f32) {
        match receiver {
            Receiver::Vertex { index, part } => (
                part.and_then(|k| self.part_gains.get(k).copied())
                    .unwrap_or(self.ground.gain),
                self.vertex_offsets.get(index).copied().unwrap_or(0.0),
            ),
            Receiver::Ground => (self.ground.gain, self.ground.offset(p)),
            Receiver::Other => (self.ground.gain, 0.0),
        }
    }
}

impl StaticBase {
    /// The offset a GPU lookup is given for `receiver` at `p`.
    pub fn offset(&self, receiver: Receiver, p: Vec3) -> f32 {
        self.terms(receiver, p).1
    }
}

/// The least-squares gain of `truth`'s change on `grids`' change, each
/// receiver's values centred on its own mean: Σ t̃·g̃ / Σ g̃², clamped to
/// [0, 2]; 1 when the grids never change. `truth` and `grids` hold per
/// frame every receiver's value; `receivers` picks the ones pooled.
pub fn gain(truth: &[Vec<f32>], grids: &[Vec<f32>], receivers: &[usize]) -> f32 {
    let frames = truth.len().max(1) as f64;
    let (mut cross, mut square) = (0.0f64, 0.0f64);
    for &r in receivers {
        let t_mean: f64 = truth.iter().map(|f| f64::from(f[r])).sum::<f64>() / frames;
        let g_mean: f64 = grids.iter().map(|f| f64::from(f[r])).sum::<f64>() / frames;
        for (t, g) in truth.iter().zip(grids) {
            let (dt, dg) = (f64::from(t[r]) - t_mean, f64::from(g[r]) - g_mean);
            cross += dt * dg;
            square += dg * dg;
        }
    }
    if square <= 1e-12 {
        1.0
    } else {
        (cross / square).clamp(0.0, 2.0) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ground_offset_is_bilinear_inside_the_square_and_zero_outside() {
        let ground = GroundBase {
            square: GroundSquare {
                min: [-1.0, -1.0],
                size: 2.0,
                height: 0.0,
                resolution: 2,
            },
            gain: 1.0,
            // Texel centres at x, z = ±0.5.
            offsets: vec![0.0, 1.0, 2.0, 3.0],
        };
        assert_eq!(ground.offset(Vec3::new(-0.5, 0.0, -0.5)), 0.0);
        assert_eq!(ground.offset(Vec3::new(0.5, 0.0, 0.5)), 3.0);
        assert!((ground.offset(Vec3::ZERO) - 1.5).abs() < 1e-6);
        // Clamped to the edge texels between the edge and their centres.
        assert_eq!(ground.offset(Vec3::new(-0.9, 0.0, -0.9)), 0.0);
        assert_eq!(ground.offset(Vec3::new(1.5, 0.0, 0.0)), 0.0);
        let c = ground.square.texel_centres();
        assert_eq!(c[1], Vec3::new(0.5, 0.0, -0.5));
    }

    #[test]
    fn the_gain_follows_the_truths_change_and_ignores_its_level() {
        // Truth = 0.3 + 0.5·grids per receiver (levels differ): gain 0.5.
        let grids = vec![vec![0.1, 0.5], vec![0.3, 0.2], vec![0.2, 0.9]];
        let truth: Vec<Vec<f32>> = grids
            .iter()
            .map(|f| vec![0.3 + 0.5 * f[0], 0.7 + 0.5 * f[1]])
            .collect();
        assert!((gain(&truth, &grids, &[0, 1]) - 0.5).abs() < 1e-6);
        // Grids that never change leave the gain at 1.
        let flat = vec![vec![0.4, 0.4]; 3];
        assert_eq!(gain(&truth, &flat, &[0, 1]), 1.0);
        // A change against the truth's is clamped to 0.
        let against: Vec<Vec<f32>> = grids.iter().map(|f| vec![-f[0], -f[1]]).collect();
        assert_eq!(gain(&truth, &against, &[0, 1]), 0.0);
    }
}
