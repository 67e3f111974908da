//! `T_clip` (Malmer et al. §5.1, §5.2.2): the occlusion that a cone of
//! occluded directions casts on a receiver, clipped by the receiver's
//! tangent plane and weighted by the cosine to its normal, tabulated over
//! the cone's aperture and its angle to the normal; and the blending
//! coefficient f that moves the cone's axis towards the normal,
//! d′ = normalize(f·d + (1 − f)·n), so that d′ is the mean direction of
//! the clipped cone.
//!
//! The aperture is the occluded fraction of the sphere α = ao′ (what the
//! grid stores): a cone of half-angle θ with cos θ = 1 − 2α covers it.
//! Rows run over α in [0, 1], columns over cos β in [−1, 1], both with
//! their end points on the first and last sample; the lookup is bilinear,
//! written once here and once in `shaders/wgsl/grid_ao.wgsl`.

use serde::{Deserialize, Serialize};

/// Quadrature steps over the cone's polar angle and azimuth.
const POLAR_STEPS: usize = 96;
const AZIMUTH_STEPS: usize = 192;

/// The table: `resolution²` entries of (occlusion, f), row-major over α.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TClip {
    /// Samples along each axis.
    pub resolution: usize,
    /// (occlusion, f) per entry, α-major.
    pub values: Vec<[f32; 2]>,
}

impl TClip {
    /// Integrates every entry (deterministic quadrature, no randomness).
    pub fn compute(resolution: usize) -> Self {
        let r = resolution.max(2);
        let mut values = Vec::with_capacity(r * r);
        for a in 0..r {
            let alpha = a as f64 / (r - 1) as f64;
            for b in 0..r {
                let cos_beta = -1.0 + 2.0 * b as f64 / (r - 1) as f64;
                values.push(entry(alpha, cos_beta));
            }
        }
        Self {
            resolution: r,
            values,
        }
    }

    /// (occlusion, f) at aperture `alpha` (ao′, 0..1) and `cos_beta`, by
    /// bilinear interpolation (clamped at the table's edges).
    pub fn lookup(&self, alpha: f32, cos_beta: f32) -> [f32; 2] {
        let r = self.resolution;
        let last = (r - 1) as f32;
        let u = (alpha.clamp(0.0, 1.0)) * last;
        let v = ((cos_beta.clamp(-1.0, 1.0) + 1.0) * 0.5) * last;
        let (u0, v0) = (u.floor().min(last - 1.0), v.floor().min(last - 1.0));
        let (fu, fv) = (u - u0, v - v0);
        let (i, j) = (u0 as usize, v0 as usize);
        let at = |a: usize, b: usize| self.values[a * r + b];
        std::array::from_fn(|c| {
            let top = at(i, j)[c] + (at(i, j + 1)[c] - at(i, j)[c]) * fv;
            let bottom = at(i + 1, j)[c] + (at(i + 1, j + 1)[c] - at(i + 1, j)[c]) * fv;
            top + (bottom - top) * fu
        })
    }
}

/// One entry: the receiver's normal is +z, the cone's axis is at angle β
/// from it in the xz-plane.
fn entry(alpha: f64, cos_beta: f64) -> [f32; 2] {
    use std::f64::consts::PI;
    if alpha <= 0.0 {
        return [0.0, 1.0];
    }
    let cos_theta = 1.0 - 2.0 * alpha;
    let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt();
    // Cone frame: axis d = (sin β, 0, cos β), e1 = (cos β, 0, −sin β), e2 = y.
    let d = [sin_beta, 0.0, cos_beta];
    let e1 = [cos_beta, 0.0, -sin_beta];
    let solid = 2.0 * PI * (1.0 - cos_theta);
    let weight = solid / (POLAR_STEPS * AZIMUTH_STEPS) as f64;
    let (mut occlusion, mut mean) = (0.0f64, [0.0f64; 3]);
    for i in 0..POLAR_STEPS {
        // Uniform in cos of the polar angle: equal solid angle per step.
        let mu = 1.0 - (1.0 - cos_theta) * (i as f64 + 0.5) / POLAR_STEPS as f64;
        let s = (1.0 - mu * mu).max(0.0).sqrt();
        for k in 0..AZIMUTH_STEPS {
            let phi = 2.0 * PI * (k as f64 + 0.5) / AZIMUTH_STEPS as f64;
            let (sp, cp) = phi.sin_cos();
            let w = [
                mu * d[0] + s * cp * e1[0],
                s * sp,
                mu * d[2] + s * cp * e1[2],
            ];
            if w[2] > 0.0 {
                occlusion += w[2] * weight / PI;
                for c in 0..3 {
                    mean[c] += w[c] * weight;
                }
            }
        }
    }
    // f: the mean clipped direction is at angle γ from the normal; the
    // blend f·d + (1 − f)·n has that angle when tan γ = f sin β /
    // (f cos β + 1 − f).
    let f = if sin_beta < 1e-9 || (mean[0] == 0.0 && mean[2] == 0.0) {
        1.0
    } else {
        let tan_gamma = mean[0] / mean[2].max(1e-12);
        (tan_gamma / (sin_beta + tan_gamma * (1.0 - cos_beta))).clamp(0.0, 1.0)
    };
    [occlusion.clamp(0.0, 1.0) as f32, f as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_holds_its_closed_forms() {
        let t = TClip::compute(33);
        // Nothing occluded; everything occluded.
        assert_eq!(t.lookup(0.0, 0.3)[0], 0.0);
        assert!((t.lookup(1.0, 0.3)[0] - 1.0).abs() < 1e-3);
        // Half the sphere: the hemisphere above the receiver is all of its
        // AO, the one below none of it.
        assert!((t.lookup(0.5, 1.0)[0] - 1.0).abs() < 1e-3);
        assert!(t.lookup(0.5, -1.0)[0] < 1e-3);
        // A cone of half-angle θ on the normal: sin²θ (= 4α(1 − α)).
        let alpha = 0.125;
        let exact = 4.0 * alpha * (1.0 - alpha);
        assert!((t.lookup(alpha, 1.0)[0] - exact).abs() < 2e-3);
        // Half a hemisphere seen edge on (β = 90°, α = ½): ½.
        assert!((t.lookup(0.5, 0.0)[0] - 0.5).abs() < 2e-3);
        // A cone wholly above the plane keeps its axis: f = 1.
        assert!((t.lookup(0.05, 0.5)[1] - 1.0).abs() < 1e-2);
        // Half a sphere seen edge on: the clipped part's mean direction
        // lies between the axis and the normal.
        let f = t.lookup(0.5, 0.0)[1];
        assert!(f > 0.2 && f < 0.8, "{f}");
    }
}
