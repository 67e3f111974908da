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

use crate::method::ground::GroundBase;
use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::{
    continuous, discrete,
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

    /// The phase of clip time `t` (seconds), cyclic; 0 for a clip of no
    /// duration, and where `t / duration` is not a finite number (a NaN
    /// time, or a ratio beyond f32: no phase is nearer than another).
    pub fn phase(&self, t: f32) -> f32 {
        let cycles = t / self.duration;
        if self.duration > 0.0 && cycles.is_finite() {
            cycles.rem_euclid(1.0)
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
    /// The static ground the cubemap's change rides on there (aobake's
    /// product form, format 1.5); `None`: the cubemap alone everywhere.
    pub ground: Option<GroundBase>,
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
        self.texels.len() + self.ground.as_ref().map_or(0, |g| 2 * g.offsets.len())
    }

    /// The occlusion at a point `p` of the ground plane at `phase`: with a
    /// static ground, `clamp(gain · cubemap + offset(p), 0, 1)` (the
    /// cubemap says what the clip changes, the texture what it does not);
    /// without, [`Self::occlusion`].
    pub fn ground_ao(&self, p: Vec3, phase: f32) -> f32 {
        let c = self.occlusion(p, phase);
        self.ground.as_ref().map_or(c, |g| g.ao(c, p))
    }

    /// The gain and offset the GPU lookups (`cubemap_ground_ao`) take for
    /// a ground point `p`: the static ground's, or (1, 0) without one.
    pub fn ground_terms(&self, p: Vec3) -> (f32, f32) {
        self.ground
            .as_ref()
            .map_or((1.0, 0.0), |g| (g.gain, g.offset(p)))
    }
}
