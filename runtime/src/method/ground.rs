//! A texture of per-texel values on the ground plane, with the gain of a
//! model's change on it: the static ground both
//! the grids' base ([`super::grid::base`]) and the cubemaps' ground
//! ([`super::cubemap::model::CubemapModel::ground_ao`]) ride on.
//!
//! For a ground point `p` whose model gives `m(p)` at a frame:
//!
//! ```text
//! ao(p) = clamp(gain · m(p) + offset(p), 0, 1)
//! ```
//!
//! `offset` a square texture on the plane (bilinear between texel
//! centres, clamped to the edge texels inside the square; 0 outside it).

use glam::{Vec2, Vec3};
use half::f16;
use serde::{Deserialize, Serialize};

use crate::container::{AssetError, Container, Data};

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

impl GroundBase {
    /// `clamp(gain · model + offset(p), 0, 1)`: the ground's occlusion at
    /// `p` from the model's value there.
    pub fn ao(&self, model: f32, p: Vec3) -> f32 {
        (self.gain * model + self.offset(p)).clamp(0.0, 1.0)
    }

    /// The words the GPU lookups read (`shaders/wgsl/common/
    /// ground_texture.wgsl`): texels per side, the f32 bits of the
    /// square's min x, min z and side and of the gain, then each offset's
    /// f32 bits. An engine without such a reader uploads the offsets as a
    /// filtered texture instead.
    pub fn gpu_words(&self) -> Vec<u32> {
        let q = &self.square;
        let mut words = vec![
            u32::try_from(q.resolution).unwrap_or(u32::MAX),
            q.min[0].to_bits(),
            q.min[1].to_bits(),
            q.size.to_bits(),
            self.gain.to_bits(),
        ];
        words.extend(self.offsets.iter().map(|x| x.to_bits()));
        words
    }

    /// The offsets as the asset stores them (f16).
    pub fn section_data(&self) -> Data {
        halves(&self.offsets)
    }

    /// A ground base from its square, gain and offsets section `tag`, every
    /// number checked.
    pub fn read(
        container: &Container,
        square: GroundSquare,
        gain: f32,
        tag: &[u8; 4],
    ) -> Result<Self, AssetError> {
        let g = &square;
        if !(1..=MAX_RESOLUTION).contains(&g.resolution) {
            return Err(bad(&format!(
                "the ground's resolution must be between 1 and {MAX_RESOLUTION}"
            )));
        }
        if !(g.min.iter().all(|x| x.is_finite())
            && g.height.is_finite()
            && g.size.is_finite()
            && g.size > 0.0)
        {
            return Err(bad("the ground square is not finite and positive"));
        }
        if !gain.is_finite() {
            return Err(bad("the ground's gain must be finite"));
        }
        Ok(Self {
            square,
            gain,
            offsets: read_halves(container, tag, g.texels())?,
        })
    }
}

/// Most texels per side of a ground square.
pub const MAX_RESOLUTION: usize = 1024;

/// Values as an f16 section.
pub fn halves(v: &[f32]) -> Data {
    Data::F16(v.iter().map(|&x| f16::from_f32(x)).collect())
}

/// Section `tag` as `len` finite f16 values.
pub fn read_halves(
    container: &Container,
    tag: &[u8; 4],
    len: usize,
) -> Result<Vec<f32>, AssetError> {
    let name = String::from_utf8_lossy(tag).into_owned();
    let Data::F16(v) = container.section(tag)? else {
        return Err(bad(&format!("{name} must be f16")));
    };
    if v.len() != len || v.iter().any(|x| !x.is_finite()) {
        return Err(bad(&format!("{name} must hold {len} finite numbers")));
    }
    Ok(v.iter().map(|x| x.to_f32()).collect())
}

fn bad(what: &str) -> AssetError {
    AssetError::Malformed(what.to_owned())
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
}
