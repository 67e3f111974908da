//! Animation clips: keyframed channels and their sampling as glTF specifies
//! (spec §3.11 and Appendix C).

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::rig::skeleton::Transform;

/// What a channel animates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Property {
    /// Local translation (3 numbers per key).
    Translation,
    /// Local rotation (quaternion x, y, z, w per key).
    Rotation,
    /// Local scale (3 numbers per key).
    Scale,
    /// Morph-target weights (one number per target per key).
    Weights,
}

/// How values between keys are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// Hold the previous key.
    Step,
    /// Lerp, or slerp for rotations.
    Linear,
    /// Hermite spline with in- and out-tangents per key.
    CubicSpline,
}

/// One animated property of one node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channel {
    /// The character's node.
    pub node: usize,
    /// What is animated.
    pub property: Property,
    /// Interpolation between keys.
    pub interpolation: Interpolation,
    /// Key times in seconds, non-decreasing, finite.
    pub times: Vec<f32>,
    /// Values per key: `width` numbers, or `3 * width` for cubic splines
    /// (in-tangent, value, out-tangent).
    pub values: Vec<f32>,
    /// Numbers per value (3, 4, or the morph target count).
    pub width: usize,
}

/// A named animation bound to a character's nodes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Clip {
    /// The animation's name, or `animation_N` when it has none.
    pub name: String,
    /// The channels that target nodes of the character.
    pub channels: Vec<Channel>,
    /// The largest key time: the clip plays over `0..=duration`.
    pub duration: f32,
}

impl Channel {
    /// The value at time `t` (seconds), written into `out` (`width` long).
    /// Before the first key the first value holds, after the last key the
    /// last one.
    pub fn sample_into(&self, t: f32, out: &mut [f32]) {
        let w = self.width;
        let stride = match self.interpolation {
            Interpolation::CubicSpline => 3 * w,
            _ => w,
        };
        let value_at = |k: usize| -> &[f32] {
            let base = k * stride
                + if self.interpolation == Interpolation::CubicSpline {
                    w
                } else {
                    0
                };
            &self.values[base..base + w]
        };
        let n = self.times.len();
        // Index of the first key strictly after t.
        let next = self.times.partition_point(|&k| k <= t);
        if next == 0 {
            out.copy_from_slice(value_at(0));
            return;
        }
        if next >= n {
            out.copy_from_slice(value_at(n - 1));
            return;
        }
        let k = next - 1;
        let (t0, t1) = (self.times[k], self.times[next]);
        let dt = t1 - t0;
        if dt <= 0.0 || self.interpolation == Interpolation::Step {
            out.copy_from_slice(value_at(k));
            return;
        }
        let s = (t - t0) / dt;
        match self.interpolation {
            Interpolation::Step => unreachable!("handled above"),
            Interpolation::Linear if self.property == Property::Rotation => {
                let q0 = Quat::from_slice(value_at(k));
                let q1 = Quat::from_slice(value_at(next));
                out.copy_from_slice(&q0.slerp(q1, s).to_array());
            }
            Interpolation::Linear => {
                for ((o, a), b) in out.iter_mut().zip(value_at(k)).zip(value_at(next)) {
                    *o = a + (b - a) * s;
                }
            }
            Interpolation::CubicSpline => {
                // p(s) = (2s³-3s²+1)v0 + (s³-2s²+s)·dt·b0 + (-2s³+3s²)v1 + (s³-s²)·dt·a1,
                // b0 the out-tangent of key k, a1 the in-tangent of key k+1.
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                let v0 = &self.values[k * stride + w..k * stride + 2 * w];
                let b0 = &self.values[k * stride + 2 * w..k * stride + 3 * w];
                let a1 = &self.values[next * stride..next * stride + w];
                let v1 = &self.values[next * stride + w..next * stride + 2 * w];
                for i in 0..w {
                    out[i] = h00 * v0[i] + h10 * dt * b0[i] + h01 * v1[i] + h11 * dt * a1[i];
                }
                if self.property == Property::Rotation {
                    let q = Quat::from_slice(out).normalize();
                    out.copy_from_slice(&q.to_array());
                }
            }
        }
    }

    /// Applies the channel at time `t` to a node's transform or weights.
    pub(crate) fn apply(&self, t: f32, transform: &mut Transform, weights: &mut [f32]) {
        match self.property {
            Property::Weights => {
                if weights.len() == self.width {
                    self.sample_into(t, weights);
                }
            }
            Property::Rotation => {
                let mut q = [0.0; 4];
                self.sample_into(t, &mut q);
                transform.rotation = Quat::from_array(q).normalize();
            }
            Property::Translation | Property::Scale => {
                let mut v = [0.0; 3];
                self.sample_into(t, &mut v);
                let v = Vec3::from_array(v);
                if self.property == Property::Translation {
                    transform.translation = v;
                } else {
                    transform.scale = v;
                }
            }
        }
    }

    /// Number of keys.
    pub fn keys(&self) -> usize {
        self.times.len()
    }
}

impl Clip {
    /// Every key time of the clip's channels, sorted and deduplicated.
    pub fn key_times(&self) -> Vec<f32> {
        let mut times: Vec<f32> = self
            .channels
            .iter()
            .flat_map(|c| c.times.iter().copied())
            .collect();
        times.sort_by(f32::total_cmp);
        times.dedup();
        times
    }

    /// Every key time and every frame at `fps`, sorted; when that is more
    /// than `max` times, `max` of them evenly spread over the list.
    pub fn sample_times(&self, fps: f32, max: usize) -> Vec<f32> {
        let mut times = self.key_times();
        times.extend(self.frame_times(fps));
        times.sort_by(f32::total_cmp);
        times.dedup();
        if times.len() <= max || max == 0 {
            return times;
        }
        let step = (times.len() - 1) as f64 / (max - 1).max(1) as f64;
        (0..max)
            .map(|i| times[((i as f64 * step).round() as usize).min(times.len() - 1)])
            .collect()
    }

    /// Times `0, 1/fps, 2/fps, ...` up to and including the duration.
    pub fn frame_times(&self, fps: f32) -> Vec<f32> {
        let frames = (self.duration * fps).floor() as usize;
        let mut times: Vec<f32> = (0..=frames).map(|i| i as f32 / fps).collect();
        if times.last().is_some_and(|&t| t < self.duration) {
            times.push(self.duration);
        }
        times
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(
        interpolation: Interpolation,
        property: Property,
        times: &[f32],
        values: &[f32],
        width: usize,
    ) -> Channel {
        Channel {
            node: 0,
            property,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
            width,
        }
    }

    fn at(c: &Channel, t: f32) -> Vec<f32> {
        let mut out = vec![0.0; c.width];
        c.sample_into(t, &mut out);
        out
    }

    #[test]
    fn linear_step_and_clamping() {
        let c = channel(
            Interpolation::Linear,
            Property::Translation,
            &[1.0, 3.0],
            &[0., 0., 0., 2., 4., 6.],
            3,
        );
        assert_eq!(at(&c, 0.0), vec![0., 0., 0.]);
        assert_eq!(at(&c, 2.0), vec![1., 2., 3.]);
        assert_eq!(at(&c, 9.0), vec![2., 4., 6.]);
        let s = Channel {
            interpolation: Interpolation::Step,
            ..c
        };
        assert_eq!(at(&s, 2.9), vec![0., 0., 0.]);
        assert_eq!(at(&s, 3.0), vec![2., 4., 6.]);
    }

    #[test]
    fn rotations_slerp_on_the_short_arc() {
        let q0 = Quat::IDENTITY;
        let q1 = -Quat::from_rotation_z(std::f32::consts::FRAC_PI_2); // same rotation, other hemisphere
        let mut values = q0.to_array().to_vec();
        values.extend(q1.to_array());
        let c = channel(
            Interpolation::Linear,
            Property::Rotation,
            &[0.0, 1.0],
            &values,
            4,
        );
        let q = Quat::from_slice(&at(&c, 0.5));
        let expect = Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
        assert!(q.dot(expect).abs() > 1.0 - 1e-6, "{q:?}");
    }

    #[test]
    fn cubic_spline_is_hermite() {
        // Scalar: keys at 0 (value 0, out-tangent 1) and 2 (value 1, in-tangent 0).
        let values = [0.0, 0.0, 1.0, 0.0, 1.0, 0.0];
        let c = channel(
            Interpolation::CubicSpline,
            Property::Weights,
            &[0.0, 2.0],
            &values,
            1,
        );
        // s = 0.5: h00=0.5, h10=0.125, h01=0.5, h11=-0.125; dt=2.
        let expect = 0.5 * 0.0 + 0.125 * 2.0 * 1.0 + 0.5 * 1.0 + -0.125 * 2.0 * 0.0;
        assert!((at(&c, 1.0)[0] - expect).abs() < 1e-6);
        assert_eq!(at(&c, 2.0)[0], 1.0);
        assert_eq!(at(&c, -1.0)[0], 0.0);
    }

    #[test]
    fn frame_times_cover_the_duration() {
        let clip = Clip {
            name: "c".into(),
            channels: vec![],
            duration: 1.05,
        };
        let t = clip.frame_times(10.0);
        assert_eq!(t.len(), 12);
        assert_eq!(*t.last().unwrap(), 1.05);
    }
}
