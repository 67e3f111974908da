//! Where Kroon's nested spheroidal cubemaps sit (Kroon 2023, §3.2.1,
//! §3.3.1): a spheroid around the character over its whole clip, shells
//! nested inside it, and a texel per direction on each of six cube faces.
//!
//! * The **centre** is the centre of the bounding box of every vertex over
//!   the clip's time samples; the **radii** are, per axis, the largest
//!   distance of a vertex from the centre along that axis (a spheroid, not
//!   a sphere: a standing human is taller than wide). Where the thesis
//!   stops there, aobake then grows the radii uniformly until the farthest
//!   vertex lies on the spheroid: per-axis maxima alone can leave a hand
//!   raised to a corner of the box outside every shell.
//! * **Outer scaling** (≥ 1 for a margin) scales the whole spheroid; shell
//!   `k` of `S_d` lies at the normalised radius
//!   `ρ_k = inner + (1 − inner)·(k + 1)/S_d`: with `inner` = 0 the shells
//!   are evenly spaced from the centre to the outside (Kroon's reference
//!   scaling, Fig. 3.4a), a larger `inner` pushes them outwards where the
//!   occlusion a character casts is (his inner scaling, Fig. 3.4b).
//! * A texel's **direction** is the standard cube-map direction of its
//!   centre (the OpenGL/Direct3D face order and orientation), normalised;
//!   the sample point of texel direction `u` on shell `k` is
//!   `centre + outer · ρ_k · (radii ⊙ u)`.
//!
//! A point `p` in space maps back through the same spheroid: its
//! direction is `(p − centre) ⊘ radii` and its normalised radial distance
//! `|(p − centre) ⊘ radii| / outer`; beyond 1 it is outside every shell.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Cube faces in the standard order: +x, −x, +y, −y, +z, −z.
pub const FACES: usize = 6;

/// The faces' names, in that order.
pub const FACE_NAMES: [&str; FACES] = ["+x", "-x", "+y", "-y", "+z", "-z"];

/// The spheroid and its shells.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Spheroid {
    /// Centre of the clip's bounding box.
    pub centre: Vec3,
    /// Largest distance from the centre per axis (each > 0).
    pub radii: Vec3,
    /// Outer scaling: the margin around the character (≥ 1 typical).
    pub outer: f32,
    /// Inner scaling in [0, 1): where the innermost shell's spacing starts.
    pub inner: f32,
    /// Number of shells, `S_d`.
    pub shells: usize,
}

impl Spheroid {
    /// The spheroid around `frames` (each a posed mesh's positions): the
    /// centre of their common bounding box, the per-axis radii about it.
    /// A degenerate axis (a flat or empty character) gets a small radius
    /// so that the spheroid stays invertible.
    pub fn around<'a>(
        frames: impl IntoIterator<Item = &'a [Vec3]> + Clone,
        outer: f32,
        inner: f32,
        shells: usize,
    ) -> Self {
        let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for frame in frames.clone() {
            for &p in frame {
                min = min.min(p);
                max = max.max(p);
            }
        }
        if !(min.is_finite() && max.is_finite()) {
            (min, max) = (Vec3::ZERO, Vec3::ZERO);
        }
        let centre = 0.5 * (min + max);
        let mut radii = Vec3::ZERO;
        let frames_again = frames.clone();
        for frame in frames {
            for &p in frame {
                radii = radii.max((p - centre).abs());
            }
        }
        let floor = 1e-3 * radii.max_element().max(1e-3);
        let mut radii = radii.max(Vec3::splat(floor));
        // Per-axis radii can leave a vertex outside the spheroid (a hand
        // raised to a corner of the box); grow them uniformly until the
        // farthest vertex lies on it.
        let mut reach = 1.0f32;
        for frame in frames_again {
            for &p in frame {
                reach = reach.max(((p - centre) / radii).length());
            }
        }
        radii *= reach;
        Self {
            centre,
            radii,
            outer,
            inner,
            shells,
        }
    }

    /// Normalised radius `ρ_k` of shell `k` (the outermost is 1).
    pub fn shell_radius(&self, k: usize) -> f32 {
        self.inner + (1.0 - self.inner) * (k + 1) as f32 / self.shells as f32
    }

    /// The sample point of direction `u` (unit) on shell `k`.
    pub fn point(&self, u: Vec3, k: usize) -> Vec3 {
        self.centre + self.outer * self.shell_radius(k) * (self.radii * u)
    }

    /// The direction (unit) and normalised radial distance of a point:
    /// 1 on the outermost shell, more outside it.
    pub fn locate(&self, p: Vec3) -> (Vec3, f32) {
        let q = (p - self.centre) / self.radii;
        let len = q.length();
        let dir = if len > 0.0 { q / len } else { Vec3::Y };
        (dir, len / self.outer)
    }
}

/// The direction through texel coordinates `(s, t)` ∈ [0, 1]² of `face`
/// (not normalised), in the standard cube-map convention.
pub fn face_direction(face: usize, s: f32, t: f32) -> Vec3 {
    let (a, b) = (2.0 * s - 1.0, 2.0 * t - 1.0);
    match face {
        0 => Vec3::new(1.0, -b, -a),
        1 => Vec3::new(-1.0, -b, a),
        2 => Vec3::new(a, 1.0, b),
        3 => Vec3::new(a, -1.0, -b),
        4 => Vec3::new(a, -b, 1.0),
        _ => Vec3::new(-a, -b, -1.0),
    }
}

/// The unit direction of texel `(i, j)`'s centre on a `res`² face.
pub fn texel_direction(face: usize, i: usize, j: usize, res: usize) -> Vec3 {
    let s = (i as f32 + 0.5) / res as f32;
    let t = (j as f32 + 0.5) / res as f32;
    face_direction(face, s, t).normalize()
}

/// The face of a direction and its texel coordinates `(s, t)` ∈ [0, 1]²:
/// the inverse of [`face_direction`].
pub fn face_of(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    let (face, sc, tc, ma) = if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 {
            (0, -d.z, -d.y, a.x)
        } else {
            (1, d.z, -d.y, a.x)
        }
    } else if a.y >= a.z {
        if d.y >= 0.0 {
            (2, d.x, d.z, a.y)
        } else {
            (3, d.x, -d.z, a.y)
        }
    } else if d.z >= 0.0 {
        (4, d.x, -d.y, a.z)
    } else {
        (5, -d.x, -d.y, a.z)
    };
    let ma = ma.max(f32::MIN_POSITIVE);
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_texel_direction_maps_back_to_its_texel() {
        let res = 16;
        for face in 0..FACES {
            for j in 0..res {
                for i in 0..res {
                    let d = texel_direction(face, i, j, res);
                    assert!((d.length() - 1.0).abs() < 1e-5);
                    let (f, s, t) = face_of(d);
                    assert_eq!(f, face, "texel {i},{j} of face {face}");
                    assert_eq!(
                        ((s * res as f32) as usize, (t * res as f32) as usize),
                        (i, j)
                    );
                }
            }
        }
    }

    #[test]
    fn faces_point_along_their_axes() {
        let axes = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        for (face, axis) in axes.into_iter().enumerate() {
            assert_eq!(face_direction(face, 0.5, 0.5), axis);
            assert_eq!(face_of(axis), (face, 0.5, 0.5));
        }
    }

    #[test]
    fn the_spheroid_holds_every_vertex_and_maps_its_shells_back() {
        let a = [Vec3::new(-0.3, 0.0, -0.2), Vec3::new(0.3, 1.8, 0.1)];
        let b = [Vec3::new(0.1, 0.2, 0.2), Vec3::new(-0.1, 1.0, -0.1)];
        let s = Spheroid::around([&a[..], &b[..]], 1.1, 0.25, 8);
        assert_eq!(s.centre, Vec3::new(0.0, 0.9, 0.0));
        // Per-axis maxima (0.3, 0.9, 0.2), grown until the corner vertex
        // (1, 1, 1) in normalised units, at √3, lies on the spheroid.
        let grown = Vec3::new(0.3, 0.9, 0.2) * 3f32.sqrt();
        assert!((s.radii - grown).length() < 1e-5, "{}", s.radii);
        let mut farthest = 0.0f32;
        for p in a.iter().chain(&b) {
            let (_, d) = s.locate(*p);
            farthest = farthest.max(d);
            assert!(d <= 1.0 / 1.1 + 1e-6, "{p} at {d}");
        }
        assert!(
            (farthest - 1.0 / 1.1).abs() < 1e-5,
            "a vertex on the spheroid"
        );
        assert!((s.shell_radius(7) - 1.0).abs() < 1e-6);
        assert!((s.shell_radius(0) - (0.25 + 0.75 / 8.0)).abs() < 1e-6);
        let u = texel_direction(2, 3, 5, 16);
        for k in 0..8 {
            let (dir, d) = s.locate(s.point(u, k));
            assert!((dir - u).length() < 1e-5);
            assert!((d - s.shell_radius(k)).abs() < 1e-5);
        }
    }

    #[test]
    fn an_empty_or_flat_character_still_gets_an_invertible_spheroid() {
        let s = Spheroid::around(std::iter::empty::<&[Vec3]>(), 1.1, 0.0, 8);
        assert!(s.radii.min_element() > 0.0);
        let flat = [Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)];
        let s = Spheroid::around([&flat[..]], 1.1, 0.0, 8);
        assert!(s.radii.y > 0.0);
        let (dir, d) = s.locate(Vec3::new(0.5, 0.0, 0.0));
        assert!(dir.is_finite() && d.is_finite());
    }
}
