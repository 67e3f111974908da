//! Kroon's *continuous radial distance* encoding of one texel's
//! (time × distance) field (Kroon 2023, §3.4, §4.1.2): a 5 × 5 cosine
//! basis over the whole field plus two residual cubics, one along the
//! distance axis and then one along the time axis, fitted with too-bright
//! residuals weighted 0.6. A texel takes 64 bytes, four cubemaps of 16.
//!
//! Where aobake departs from the thesis, and why:
//! * **One channel, not Blurhash's three.** The thesis fed Blurhash's
//!   three colour channels three thirds of the time axis (a workaround it
//!   calls out for the jumps it leaves at the seams); aobake codes the
//!   whole field in one 5 × 5 cosine basis, `cos(π i x) cos(π j y)` at the
//!   sample centres `x = (τ + ½)/S_t`, `y = (k + ½)/S_d` (DCT-II, whose
//!   sampled bases are orthogonal, so the 25 coefficients are the
//!   least-squares fit of the field).
//! * **Packing.** Blurhash's base-83 digits (54 bytes for 5 × 5 × 3,
//!   one bit of every byte unused) become 25 half floats (50 bytes): more
//!   precision in fewer bytes. Each residual cubic is stored as its values
//!   at the four nodes 0, ⅓, ⅔, 1 of its axis (Lagrange form; bounded by
//!   the residuals themselves, unlike monomial coefficients), one signed
//!   byte each in steps of 0.5/127. 50 + 8 = 58 of the 64 bytes are used.
//! * The residual curves are fitted to the *quantised* basis's output,
//!   exactly what the run time decodes, and the time curve to what is left
//!   after the quantised distance curve.
//!
//! Byte layout of a texel: bytes `2(5i + j)..` hold the f16 coefficient of
//! time frequency `i` and distance frequency `j` (little-endian), bytes
//! 50..54 the distance cubic's nodes, 54..58 the time cubic's, 58..64 are
//! zero.

use half::f16;

/// Cosine frequencies per axis.
pub const BASIS: usize = 5;
/// Bytes per texel: four cubemaps of 16.
pub const BYTES: usize = 64;
/// Cubemaps the encoding fills.
pub const CUBEMAPS: usize = BYTES / 16;
/// Offset of the distance cubic's nodes.
const DISTANCE_NODES: usize = 2 * BASIS * BASIS;
/// Offset of the time cubic's nodes.
const TIME_NODES: usize = DISTANCE_NODES + 4;
/// A residual node's byte covers [−`RESIDUAL_RANGE`, `RESIDUAL_RANGE`].
pub const RESIDUAL_RANGE: f32 = 0.5;

/// How to encode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoding {
    /// Weight of too-bright residuals (decoded below the input) in the
    /// residual fits; too-dark ones weigh 1. Kroon: 0.6.
    pub bright_weight: f32,
    /// Whether to fit the residual curves at all (without them the nodes
    /// are zero: the thesis's plain "Blurhash" row).
    pub residuals: bool,
}

/// Cosine tables for a field of `times` × `shells` samples: `time[i][τ]`,
/// `distance[j][k]`. Built once per face, shared by every texel.
#[derive(Debug, Clone)]
pub struct Tables {
    times: usize,
    shells: usize,
    time: Vec<[f32; BASIS]>,
    distance: Vec<[f32; BASIS]>,
}

impl Tables {
    /// Tables for `times` time samples and `shells` shells.
    pub fn new(times: usize, shells: usize) -> Self {
        Self {
            times,
            shells,
            time: (0..times).map(|t| basis_row(times, t as f32)).collect(),
            distance: (0..shells).map(|k| basis_row(shells, k as f32)).collect(),
        }
    }
}

/// The cosine basis at continuous coordinates (time samples, shells).
fn basis_row(samples: usize, at: f32) -> [f32; BASIS] {
    let x = (at + 0.5) / samples as f32;
    std::array::from_fn(|i| (std::f32::consts::PI * i as f32 * x).cos())
}

/// Lagrange weights of the nodes 0, ⅓, ⅔, 1 at `u`.
fn lagrange(u: f32) -> [f32; 4] {
    let n = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
    std::array::from_fn(|a| {
        let mut w = 1.0;
        for b in 0..4 {
            if b != a {
                w *= (u - n[b]) / (n[a] - n[b]);
            }
        }
        w
    })
}

/// Where a shell coordinate and a time coordinate sit on their cubics'
/// axes: `[0, 1]` over the shells, `[0, 1)` over the cycle.
fn distance_axis(shells: usize, k: f32) -> f32 {
    if shells > 1 {
        (k / (shells - 1) as f32).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

fn time_axis(times: usize, tau: f32) -> f32 {
    (tau / times as f32).rem_euclid(1.0)
}

fn node_byte(v: f32) -> u8 {
    ((v.clamp(-RESIDUAL_RANGE, RESIDUAL_RANGE) / RESIDUAL_RANGE * 127.0).round() as i8) as u8
}

fn byte_node(b: u8) -> f32 {
    f32::from(b as i8) * RESIDUAL_RANGE / 127.0
}

/// The weighted least-squares cubic through `(u, r)` with weights `w`, as
/// its values at the four nodes; zero where the data cannot pin it down.
fn fit_cubic(points: impl Iterator<Item = (f32, f32, f32)>) -> [f32; 4] {
    let mut a = [[0.0f64; 4]; 4];
    let mut b = [0.0f64; 4];
    for (u, r, w) in points {
        let phi = [1.0, f64::from(u), f64::from(u * u), f64::from(u * u * u)];
        for p in 0..4 {
            b[p] += f64::from(w) * phi[p] * f64::from(r);
            for q in 0..4 {
                a[p][q] += f64::from(w) * phi[p] * phi[q];
            }
        }
    }
    let m = glam::DMat4::from_cols_array_2d(&a).transpose();
    if m.determinant().abs() < 1e-12 * a[0][0].max(1e-300).powi(4) {
        return [0.0; 4];
    }
    let c = m.inverse() * glam::DVec4::from_array(b);
    std::array::from_fn(|n| {
        let u = n as f64 / 3.0;
        (c.x + c.y * u + c.z * u * u + c.w * u * u * u) as f32
    })
}

/// Encodes one texel's field: `field[k · times + τ]` for shell `k` and
/// time sample `τ`.
pub fn encode(field: &[f32], tables: &Tables, encoding: Encoding) -> [u8; BYTES] {
    let (times, shells) = (tables.times, tables.shells);
    debug_assert_eq!(field.len(), times * shells);
    // Separable projection: over time per shell, then over the shells.
    let mut per_shell = vec![[0.0f64; BASIS]; shells];
    for (k, acc) in per_shell.iter_mut().enumerate() {
        for (tau, cos) in tables.time.iter().enumerate() {
            let v = f64::from(field[k * times + tau]);
            for i in 0..BASIS {
                acc[i] += v * f64::from(cos[i]);
            }
        }
    }
    let mut out = [0u8; BYTES];
    let mut coefficients = [[0.0f32; BASIS]; BASIS];
    for i in 0..BASIS {
        for j in 0..BASIS {
            let mut c = 0.0f64;
            for (k, acc) in per_shell.iter().enumerate() {
                c += acc[i] * f64::from(tables.distance[k][j]);
            }
            let norm = if i == 0 { 1.0 } else { 2.0 } * if j == 0 { 1.0 } else { 2.0 };
            let q = f16::from_f64(c * norm / (times * shells) as f64);
            coefficients[i][j] = q.to_f32();
            out[2 * (BASIS * i + j)..][..2].copy_from_slice(&q.to_le_bytes());
        }
    }
    // What the quantised basis decodes at every sample.
    let mut decoded = vec![0.0f32; times * shells];
    for k in 0..shells {
        let d = &tables.distance[k];
        let row: [f32; BASIS] =
            std::array::from_fn(|i| (0..BASIS).map(|j| coefficients[i][j] * d[j]).sum());
        for (tau, t) in tables.time.iter().enumerate() {
            decoded[k * times + tau] = (0..BASIS).map(|i| row[i] * t[i]).sum();
        }
    }
    fit_residuals(field, &decoded, times, shells, encoding, &mut out);
    out
}

/// Fits the residual cubics of `field` (`[k · times + τ]`) left by what a
/// basis decodes there (`decoded`, same layout): along distance, then
/// along time after the quantised distance curve; too-bright residuals
/// weigh `encoding.bright_weight`. Writes their nodes into bytes 50..58
/// of `out` (zeros without `encoding.residuals`).
pub(super) fn fit_residuals(
    field: &[f32],
    decoded: &[f32],
    times: usize,
    shells: usize,
    encoding: Encoding,
    out: &mut [u8; BYTES],
) {
    for b in &mut out[DISTANCE_NODES..TIME_NODES + 4] {
        *b = node_byte(0.0);
    }
    if !encoding.residuals {
        return;
    }
    let mut residual: Vec<f32> = field.iter().zip(decoded).map(|(f, d)| f - d).collect();
    let weight = |r: f32| if r > 0.0 { encoding.bright_weight } else { 1.0 };
    let distance = fit_cubic((0..shells * times).map(|s| {
        let r = residual[s];
        (distance_axis(shells, (s / times) as f32), r, weight(r))
    }));
    let mut nodes = [0.0f32; 4];
    for (n, v) in distance.iter().enumerate() {
        out[DISTANCE_NODES + n] = node_byte(*v);
        nodes[n] = byte_node(out[DISTANCE_NODES + n]);
    }
    for k in 0..shells {
        let l = lagrange(distance_axis(shells, k as f32));
        let p: f32 = (0..4).map(|n| l[n] * nodes[n]).sum();
        for r in &mut residual[k * times..(k + 1) * times] {
            *r -= p;
        }
    }
    let time = fit_cubic((0..shells * times).map(|s| {
        let r = residual[s];
        (time_axis(times, (s % times) as f32), r, weight(r))
    }));
    for (n, v) in time.iter().enumerate() {
        out[TIME_NODES + n] = node_byte(*v);
    }
}

/// The two residual cubics stored in bytes 50..58, at time `tau` (in
/// `0..times`) and shell `k`.
pub(super) fn residuals(bytes: &[u8; BYTES], times: usize, shells: usize, tau: f32, k: f32) -> f32 {
    let ld = lagrange(distance_axis(shells, k));
    let lt = lagrange(time_axis(times, tau));
    (0..4)
        .map(|n| {
            ld[n] * byte_node(bytes[DISTANCE_NODES + n]) + lt[n] * byte_node(bytes[TIME_NODES + n])
        })
        .sum()
}

/// The value of an [`encode`]d texel at time `tau` (time samples, cyclic)
/// and shell coordinate `k` (fractional between shells), clamped to
/// [0, 1].
pub fn decode(bytes: &[u8; BYTES], times: usize, shells: usize, tau: f32, k: f32) -> f32 {
    let tau = tau.rem_euclid(times as f32);
    let t = basis_row(times, tau);
    let d = basis_row(shells, k);
    let mut v = 0.0f32;
    for i in 0..BASIS {
        let mut row = 0.0f32;
        for j in 0..BASIS {
            let c =
                f16::from_le_bytes([bytes[2 * (BASIS * i + j)], bytes[2 * (BASIS * i + j) + 1]]);
            row += c.to_f32() * d[j];
        }
        v += row * t[i];
    }
    (v + residuals(bytes, times, shells, tau, k)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: usize = 255;
    const S: usize = 8;

    fn encoding(bright_weight: f32, residuals: bool) -> Encoding {
        Encoding {
            bright_weight,
            residuals,
        }
    }

    /// A smooth field: dark near the character (small k), a dip in time.
    fn smooth(k: usize, tau: usize) -> f32 {
        let x = tau as f32 / T as f32;
        let y = k as f32 / S as f32;
        (0.6 * (1.0 - y) * (0.7 + 0.3 * (std::f32::consts::TAU * x).cos())).clamp(0.0, 1.0)
    }

    fn errors(field: &[f32], bytes: &[u8; BYTES]) -> (f32, f32, f32) {
        let (mut dark, mut bright, mut worst) = (0.0, 0.0, 0.0f32);
        for k in 0..S {
            for tau in 0..T {
                let e = decode(bytes, T, S, tau as f32, k as f32) - field[k * T + tau];
                if e > 0.0 {
                    dark += e * e;
                } else {
                    bright += e * e;
                }
                worst = worst.max(e.abs());
            }
        }
        (dark, bright, worst)
    }

    #[test]
    fn a_field_in_the_basis_comes_back_to_half_float_precision() {
        let tables = Tables::new(T, S);
        // cos(π·2x)·cos(π·y) sampled at the centres is in the basis.
        let field: Vec<f32> = (0..S * T)
            .map(|s| {
                let (k, tau) = (s / T, s % T);
                let t = &tables.time[tau];
                let d = &tables.distance[k];
                0.4 + 0.2 * t[2] * d[1] + 0.1 * t[1]
            })
            .collect();
        let bytes = encode(&field, &tables, encoding(0.6, false));
        let (_, _, worst) = errors(&field, &bytes);
        assert!(worst < 1e-3, "worst {worst}");
        assert!(bytes[58..].iter().all(|&b| b == 0));
    }

    #[test]
    fn residual_curves_cut_the_too_dark_error_of_a_sharp_edge() {
        let tables = Tables::new(T, S);
        // Inside the mesh (1) for the innermost shells during part of the
        // cycle, a smooth falloff elsewhere: the cosine basis rings and
        // bleeds darkness outwards, as the thesis's Figure 5.5 shows.
        let field: Vec<f32> = (0..S * T)
            .map(|s| {
                let (k, tau) = (s / T, s % T);
                if k < 2 && (60..140).contains(&tau) {
                    1.0
                } else {
                    smooth(k, tau)
                }
            })
            .collect();
        let plain = encode(&field, &tables, encoding(0.6, false));
        let curves = encode(&field, &tables, encoding(0.6, true));
        let (dark_plain, bright_plain, _) = errors(&field, &plain);
        let (dark_curves, bright_curves, _) = errors(&field, &curves);
        assert!(
            dark_curves < dark_plain,
            "too dark: {dark_curves} with curves, {dark_plain} without"
        );
        // Weighting too-bright residuals at 0.6 trades some brightness for
        // less darkness; weighted evenly, the curves are a least-squares
        // correction and cannot raise the total squared error (beyond
        // quantisation and the clamp to [0, 1]).
        let even = encode(&field, &tables, encoding(1.0, true));
        let (dark_even, bright_even, _) = errors(&field, &even);
        assert!(
            dark_even + bright_even <= dark_plain + bright_plain + 1e-3,
            "{dark_even} + {bright_even} against {dark_plain} + {bright_plain}"
        );
        assert!(
            bright_curves >= bright_even - 1e-3,
            "the weight moves error to the bright side"
        );
    }

    #[test]
    fn decoding_interpolates_between_samples_and_wraps_in_time() {
        let tables = Tables::new(T, S);
        let field: Vec<f32> = (0..S * T).map(|s| smooth(s / T, s % T)).collect();
        let bytes = encode(&field, &tables, encoding(0.6, true));
        let (_, _, worst) = errors(&field, &bytes);
        assert!(worst < 0.05, "worst {worst}");
        let a = decode(&bytes, T, S, 10.0, 3.0);
        let b = decode(&bytes, T, S, 11.0, 3.0);
        let mid = decode(&bytes, T, S, 10.5, 3.0);
        assert!((mid - 0.5 * (a + b)).abs() < 0.01);
        assert_eq!(decode(&bytes, T, S, 10.0 + T as f32, 3.0), a);
    }

    #[test]
    fn residual_nodes_are_signed_bytes_with_an_exact_zero() {
        assert_eq!(byte_node(node_byte(0.0)), 0.0);
        for v in [-0.5, -0.1234, 0.0, 0.3, 0.5] {
            assert!((byte_node(node_byte(v)) - v).abs() <= 0.5 * RESIDUAL_RANGE / 127.0 + 1e-6);
        }
        let w = lagrange(0.4);
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(lagrange(1.0 / 3.0)[1], 1.0);
    }
}
