//! A baked cubemap as the run time sees it: the spheroid, the texels of
//! every cubemap layer, and the occlusion at any point in space and any
//! phase of the cycle (the CPU twin of `shaders/wgsl/cubemap_ao.wgsl`).
//!
//! **Texel layout** (what an engine uploads as a cube-map array of
//! `RGBA32Uint` texels): layer `c · 6 + face`, row `j`, column `i`, 16
//! bytes each. The discrete encoding has one cubemap per shell (layer
//! `shell · 6 + face` holds the texel's time curve on that shell); the
//! continuous one has four, holding bytes `16c..16c + 16` of a texel's 64.
//!
//! **Lookup**, for a point `p` at phase `φ` ∈ [0, 1) of the cycle:
//! * direction and normalised radius from [`Spheroid::locate`]; the
//!   direction picks a face and texel coordinates, and the four nearest
//!   texel centres are decoded and blended bilinearly (at a face's edge
//!   the coordinates are clamped to the face: no filtering across faces);
//! * the radius gives a fractional shell `k = (ρ − inner)·S_d/(1 − inner)
//!   − 1`: the discrete encoding decodes both adjacent shells and blends
//!   them, the continuous one evaluates its basis at `k` directly;
//!   inside the innermost shell the innermost value holds; beyond the
//!   outermost shell the occlusion fades linearly to 0 over one shell
//!   spacing (the thesis leaves it at 0 outside, which draws a ring where
//!   the outer shell is still occluded);
//! * the time is `τ = φ · S_t` samples, decoded continuously.
//!
//! Decoded values are blended, never coefficients (Kroon §3.3.5).

use glam::Vec3;
use serde::{Deserialize, Serialize};

use rayon::prelude::*;

use super::{
    continuous, discrete,
    face::{FaceField, dequantise},
    geometry::{FACES, Spheroid, face_of},
};

/// Which encoding a cubemap asset holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Encoding {
    /// One cubemap per shell, four quadratic time segments per texel.
    Discrete,
    /// Four cubemaps, a 5 × 5 cosine basis plus residual cubics.
    Continuous,
    /// Four cubemaps in Kroon's own continuous layout: the cycle in three
    /// thirds as the channels of a 5 × 5 Blurhash plus the same residual
    /// cubics ([`super::blurhash`]).
    Thirds,
}

impl Encoding {
    /// Cubemaps (of 16 bytes a texel) for `shells` shells.
    pub fn cubemaps(self, shells: usize) -> usize {
        match self {
            Self::Discrete => shells,
            Self::Continuous | Self::Thirds => continuous::CUBEMAPS,
        }
    }
}

/// The shape of a baked cubemap: where it sits and how it was sampled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CubemapLayout {
    /// The spheroid and its shells.
    pub spheroid: Spheroid,
    /// Texels per face edge.
    pub resolution: usize,
    /// Time samples over the cycle, `S_t`.
    pub times: usize,
    /// The encoding.
    pub encoding: Encoding,
    /// The clip's duration (seconds): a time `t` is phase `t / duration`.
    pub duration: f32,
}

impl CubemapLayout {
    /// Cubemap layers (six faces each).
    pub fn cubemaps(&self) -> usize {
        self.encoding.cubemaps(self.spheroid.shells)
    }

    /// Bytes of all texels.
    pub fn texel_bytes(&self) -> usize {
        self.cubemaps() * FACES * self.resolution * self.resolution * 16
    }

    /// Byte offset of texel `(i, j)` of `face` in cubemap `c`.
    pub fn offset(&self, c: usize, face: usize, i: usize, j: usize) -> usize {
        (((c * FACES + face) * self.resolution + j) * self.resolution + i) * 16
    }

    /// The run-time lookup of a point `p` at phase `phase` (see the
    /// module's text), with `texel(face, i, j, tau, k)` the value of a
    /// texel at time `tau` (samples) on fractional shell `k`: the model
    /// decodes its bytes there, the evaluation's uncompressed references
    /// read the raw field.
    pub fn lookup(
        &self,
        p: Vec3,
        phase: f32,
        texel: impl Fn(usize, usize, usize, f32, f32) -> f32,
    ) -> f32 {
        let s = &self.spheroid;
        let (dir, rho) = s.locate(p);
        let shells = s.shells as f32;
        let k = (rho - s.inner) * shells / (1.0 - s.inner) - 1.0;
        let fade = (shells - k).clamp(0.0, 1.0);
        if fade == 0.0 || !p.is_finite() {
            return 0.0;
        }
        let k = k.clamp(0.0, shells - 1.0);
        let tau = phase.rem_euclid(1.0) * self.times as f32;
        let (face, u, v) = face_of(dir);
        let res = self.resolution;
        let last = (res - 1) as f32;
        let x = (u * res as f32 - 0.5).clamp(0.0, last);
        let y = (v * res as f32 - 0.5).clamp(0.0, last);
        let (i0, j0) = (x.floor() as usize, y.floor() as usize);
        let (i1, j1) = ((i0 + 1).min(res - 1), (j0 + 1).min(res - 1));
        let (fx, fy) = (x - i0 as f32, y - j0 as f32);
        let top = {
            let a = texel(face, i0, j0, tau, k);
            a + fx * (texel(face, i1, j0, tau, k) - a)
        };
        let bottom = {
            let a = texel(face, i0, j1, tau, k);
            a + fx * (texel(face, i1, j1, tau, k) - a)
        };
        fade * (top + fy * (bottom - top))
    }

    /// The phase of clip time `t` (seconds), cyclic.
    pub fn phase(&self, t: f32) -> f32 {
        if self.duration > 0.0 {
            (t / self.duration).rem_euclid(1.0)
        } else {
            0.0
        }
    }
}

/// A baked cubemap.
#[derive(Debug, Clone, PartialEq)]
pub struct CubemapModel {
    /// Its shape.
    pub layout: CubemapLayout,
    /// [`CubemapLayout::texel_bytes`] bytes in the layout above.
    pub texels: Vec<u8>,
}

impl CubemapModel {
    /// The decoded value of texel `(i, j)` of `face` at time `tau`
    /// (samples) on fractional shell `k` (in `0..=S_d − 1`).
    pub fn decode_texel(&self, face: usize, i: usize, j: usize, tau: f32, k: f32) -> f32 {
        let l = &self.layout;
        let shells = l.spheroid.shells;
        match l.encoding {
            Encoding::Discrete => {
                let k0 = (k.floor() as usize).min(shells - 1);
                let k1 = (k0 + 1).min(shells - 1);
                let f = (k - k0 as f32).clamp(0.0, 1.0);
                let at = |c: usize| {
                    let o = l.offset(c, face, i, j);
                    let bytes: &[u8; 16] = self.texels[o..o + 16].try_into().expect("16 bytes");
                    discrete::decode(bytes, l.times, tau)
                };
                let a = at(k0);
                if f == 0.0 { a } else { a + f * (at(k1) - a) }
            }
            Encoding::Continuous | Encoding::Thirds => {
                let mut bytes = [0u8; continuous::BYTES];
                for c in 0..continuous::CUBEMAPS {
                    let o = l.offset(c, face, i, j);
                    bytes[16 * c..16 * c + 16].copy_from_slice(&self.texels[o..o + 16]);
                }
                if l.encoding == Encoding::Thirds {
                    super::blurhash::decode(&bytes, l.times, shells, tau, k)
                } else {
                    continuous::decode(&bytes, l.times, shells, tau, k)
                }
            }
        }
    }

    /// Occlusion at `p` at phase `phase` of the cycle.
    pub fn occlusion(&self, p: Vec3, phase: f32) -> f32 {
        self.layout.lookup(p, phase, |face, i, j, tau, k| {
            self.decode_texel(face, i, j, tau, k)
        })
    }

    /// Encodes the six faces' fields (in face order) into a model: the
    /// `assemble` job's work. `continuous` says how the continuous
    /// encoding weighs its residuals (unused by the discrete one).
    pub fn encode(
        layout: CubemapLayout,
        faces: &[FaceField],
        continuous: continuous::Encoding,
    ) -> Result<Self, String> {
        let (res, shells, times) = (layout.resolution, layout.spheroid.shells, layout.times);
        if faces.len() != FACES
            || faces
                .iter()
                .any(|f| (f.resolution, f.shells, f.times) != (res, shells, times))
        {
            return Err("the face fields do not match the cubemap's layout".into());
        }
        let tables = continuous::Tables::new(times, shells);
        let texels = res * res;
        // Every texel's bytes for every cubemap, texel-major, in parallel.
        let cubemaps = layout.cubemaps();
        let per_texel: Vec<Vec<u8>> = (0..FACES * texels)
            .into_par_iter()
            .map(|n| {
                let block: Vec<f32> = faces[n / texels]
                    .texel(n % texels)
                    .iter()
                    .map(|&b| dequantise(b))
                    .collect();
                match layout.encoding {
                    Encoding::Discrete => block
                        .chunks_exact(times)
                        .flat_map(discrete::encode)
                        .collect(),
                    Encoding::Continuous => {
                        continuous::encode(&block, &tables, continuous).to_vec()
                    }
                    Encoding::Thirds => {
                        super::blurhash::encode(&block, times, shells, continuous).to_vec()
                    }
                }
            })
            .collect();
        let mut bytes = vec![0u8; layout.texel_bytes()];
        for (n, texel) in per_texel.iter().enumerate() {
            let (face, t) = (n / texels, n % texels);
            for c in 0..cubemaps {
                let o = layout.offset(c, face, t % res, t / res);
                bytes[o..o + 16].copy_from_slice(&texel[16 * c..16 * c + 16]);
            }
        }
        Ok(Self {
            layout,
            texels: bytes,
        })
    }

    /// One face on shell `shell` at `phase`, decoded at every texel
    /// centre, rows `j` top to bottom, columns `i`: what an export writes.
    pub fn decode_face(&self, face: usize, shell: usize, phase: f32) -> Vec<f32> {
        let l = &self.layout;
        let res = l.resolution;
        let tau = phase.rem_euclid(1.0) * l.times as f32;
        let k = shell.min(l.spheroid.shells - 1) as f32;
        (0..res * res)
            .map(|t| self.decode_texel(face, t % res, t / res, tau, k))
            .collect()
    }

    /// Bytes of the texels: what a renderer keeps in memory.
    pub fn bytes(&self) -> usize {
        self.texels.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(encoding: Encoding) -> CubemapLayout {
        CubemapLayout {
            spheroid: Spheroid {
                centre: Vec3::ZERO,
                radii: Vec3::ONE,
                outer: 1.0,
                inner: 0.0,
                shells: 4,
            },
            resolution: 4,
            times: 64,
            encoding,
            duration: 2.0,
        }
    }

    /// A discrete model whose every texel on shell `k` holds the constant
    /// `values[k]`.
    fn constant_shells(values: [f32; 4]) -> CubemapModel {
        let l = layout(Encoding::Discrete);
        let mut texels = vec![0u8; l.texel_bytes()];
        for (k, v) in values.iter().enumerate() {
            let bytes = discrete::encode(&[*v; 64]);
            for face in 0..FACES {
                for j in 0..4 {
                    for i in 0..4 {
                        let o = l.offset(k, face, i, j);
                        texels[o..o + 16].copy_from_slice(&bytes);
                    }
                }
            }
        }
        CubemapModel { layout: l, texels }
    }

    #[test]
    fn shells_blend_by_radius_and_fade_out_beyond_the_last() {
        let m = constant_shells([0.8, 0.6, 0.4, 0.2]);
        let q = |x: f32| m.occlusion(Vec3::new(x, 0.0, 0.0), 0.3);
        // Shells at ρ = 0.25, 0.5, 0.75, 1; values within a byte step.
        let step = 8.0 / 255.0;
        assert!((q(0.1) - 0.8).abs() < step, "inside the first shell");
        assert!((q(0.5) - 0.6).abs() < step);
        assert!((q(0.625) - 0.5).abs() < step, "halfway between shells");
        assert!((q(1.125) - 0.1).abs() < step, "half faded");
        assert_eq!(q(1.3), 0.0);
        assert_eq!(m.occlusion(Vec3::NAN, 0.0), 0.0);
    }

    /// A smooth field on every face: darker towards the inner shells and
    /// towards +y, varying over the cycle.
    fn smooth_faces(l: &CubemapLayout) -> Vec<FaceField> {
        use super::super::geometry::texel_direction;
        let (res, shells, times) = (l.resolution, l.spheroid.shells, l.times);
        (0..FACES)
            .map(|face| {
                let mut f = FaceField::new(res, shells, times);
                for t in 0..times {
                    let phase = t as f32 / times as f32;
                    let slice: Vec<u8> = (0..shells * res * res)
                        .map(|p| {
                            let (k, texel) = (p / (res * res), p % (res * res));
                            let d = texel_direction(face, texel % res, texel / res, res);
                            let v = (0.5 - 0.1 * k as f32)
                                * (0.6 + 0.3 * d.y)
                                * (0.8 + 0.2 * (std::f32::consts::TAU * phase).cos());
                            super::super::face::quantise(v)
                        })
                        .collect();
                    f.insert(t, &slice);
                }
                f
            })
            .collect()
    }

    #[test]
    fn both_encodings_give_back_a_smooth_field_at_its_sample_points() {
        use super::super::geometry::texel_direction;
        for (encoding, tolerance) in [
            (Encoding::Discrete, 0.025),
            (Encoding::Continuous, 0.01),
            // Blurhash quantises AC terms to 19 levels: coarser.
            (Encoding::Thirds, 0.045),
        ] {
            let l = layout(encoding);
            let faces = smooth_faces(&l);
            let m = CubemapModel::encode(
                l,
                &faces,
                continuous::Encoding {
                    bright_weight: 0.6,
                    residuals: true,
                },
            )
            .unwrap();
            assert_eq!(m.bytes(), l.texel_bytes());
            let mut worst = 0.0f32;
            for (face, field) in faces.iter().enumerate() {
                for texel in [0, 5, 10, 15] {
                    let (i, j) = (texel % 4, texel / 4);
                    let d = texel_direction(face, i, j, 4);
                    for k in 0..4 {
                        for t in [0, 17, 40, 63] {
                            let p = l.spheroid.point(d, k);
                            let got = m.occlusion(p, t as f32 / 64.0);
                            let want = dequantise(field.texel(texel)[k * 64 + t]);
                            worst = worst.max((got - want).abs());
                        }
                    }
                }
            }
            assert!(worst < tolerance, "{encoding:?}: worst {worst}");
        }
        assert!(
            CubemapModel::encode(
                layout(Encoding::Discrete),
                &[],
                continuous::Encoding {
                    bright_weight: 0.6,
                    residuals: true,
                }
            )
            .is_err()
        );
    }

    #[test]
    fn the_phase_is_cyclic() {
        let l = layout(Encoding::Continuous);
        assert_eq!(l.phase(0.5), 0.25);
        assert_eq!(l.phase(2.5), 0.25);
        assert_eq!(l.phase(-0.5), 0.75);
        assert_eq!(l.cubemaps(), 4);
        assert_eq!(l.texel_bytes(), 4 * 6 * 16 * 16);
    }
}
