//! Kroon's own layout of the continuous encoding (Kroon 2023, §3.4.1,
//! §4.1.2), kept to measure aobake's departure against it on the same
//! data: the texel's (time × distance) field cut into three thirds of the
//! cycle, each third a colour channel of a Blurhash of 5 × 5 components,
//! quantised as Blurhash quantises (the DC term of each channel in 8
//! bits, the 72 AC terms in 19 square-root-companded levels under one
//! shared maximum of 83 levels), plus the same two residual cubics as
//! [`super::continuous`]. Blurhash's base-83 text becomes bits: 3 DC
//! bytes, the maximum's byte and 24 × 13 bits (three 19-level values per
//! component, 19³ < 2¹³), 43 bytes; the residual nodes at bytes 50..58 as
//! in the continuous layout. `cubemap-continuous` bakes it with
//! `cubemap.continuous_layout = "thirds"`, and every cubemap report
//! evaluates it beside the cosine layout.

use super::continuous::{self, BYTES, Encoding};

/// Components per axis.
const COMPONENTS: usize = 5;
/// Channels: thirds of the cycle.
const THIRDS: usize = 3;
/// Offset of the AC bits.
const AC: usize = 4;

/// The third of the cycle a time sample falls in, and its coordinate in
/// that third's own cosine basis.
fn third(times: usize, tau: f32) -> (usize, f32) {
    let len = times as f32 / THIRDS as f32;
    let c = ((tau / len).floor() as usize).min(THIRDS - 1);
    (c, (tau - c as f32 * len + 0.5) / len)
}

fn cosines(x: f32) -> [f32; COMPONENTS] {
    std::array::from_fn(|i| (std::f32::consts::PI * i as f32 * x).cos())
}

fn sign_pow(v: f32, e: f32) -> f32 {
    v.signum() * v.abs().powf(e)
}

/// Encodes one texel's field (`field[k · times + τ]`).
pub fn encode(field: &[f32], times: usize, shells: usize, encoding: Encoding) -> [u8; BYTES] {
    // Per third: the 5 × 5 factors, Blurhash's normalisation (1 for the
    // DC term, 2 per non-zero frequency).
    let mut factors = [[[0.0f32; COMPONENTS]; COMPONENTS]; THIRDS];
    let mut counts = [0usize; THIRDS];
    for tau in 0..times {
        let (c, x) = third(times, tau as f32);
        counts[c] += shells;
        let t = cosines(x);
        for k in 0..shells {
            let d = cosines((k as f32 + 0.5) / shells as f32);
            let v = field[k * times + tau];
            for i in 0..COMPONENTS {
                for j in 0..COMPONENTS {
                    factors[c][i][j] += v * t[i] * d[j];
                }
            }
        }
    }
    for (c, f) in factors.iter_mut().enumerate() {
        for (i, row) in f.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                let norm = if i == 0 { 1.0 } else { 2.0 } * if j == 0 { 1.0 } else { 2.0 };
                *v *= norm / counts[c].max(1) as f32;
            }
        }
    }
    let mut out = [0u8; BYTES];
    for c in 0..THIRDS {
        out[c] = (factors[c][0][0].clamp(0.0, 1.0) * 255.0).round() as u8;
    }
    let max_ac = factors
        .iter()
        .flatten()
        .flatten()
        .enumerate()
        .filter(|(n, _)| n % (COMPONENTS * COMPONENTS) != 0)
        .map(|(_, v)| v.abs())
        .fold(0.0f32, f32::max);
    let q_max = ((max_ac * 166.0 - 0.5).floor()).clamp(0.0, 82.0) as u8;
    out[3] = q_max;
    let actual_max = (f32::from(q_max) + 1.0) / 166.0;
    let mut bits = 0usize;
    for n in 1..COMPONENTS * COMPONENTS {
        let (i, j) = (n / COMPONENTS, n % COMPONENTS);
        let mut packed = 0u32;
        for f in &factors {
            let q = (sign_pow(f[i][j] / actual_max, 0.5) * 9.0 + 9.5)
                .floor()
                .clamp(0.0, 18.0) as u32;
            packed = packed * 19 + q;
        }
        for b in 0..13 {
            if packed >> b & 1 == 1 {
                out[AC + (bits + b) / 8] |= 1 << ((bits + b) % 8);
            }
        }
        bits += 13;
    }
    // The residual cubics, fitted to what the quantised thirds decode
    // (`base` at every sample, its terms dequantised and its cosines
    // computed once).
    let thirds = Thirds::of(&out);
    let at_times: Vec<(usize, [f32; COMPONENTS])> = (0..times)
        .map(|tau| {
            let (c, x) = third(times, tau as f32);
            (c, cosines(x))
        })
        .collect();
    let at_shells: Vec<[f32; COMPONENTS]> = (0..shells)
        .map(|k| cosines((k as f32 + 0.5) / shells as f32))
        .collect();
    let decoded: Vec<f32> = (0..shells * times)
        .map(|s| {
            let (c, t) = &at_times[s % times];
            thirds.at(*c, t, &at_shells[s / times])
        })
        .collect();
    continuous::fit_residuals(field, &decoded, times, shells, encoding, &mut out);
    out
}

/// One third of a texel, dequantised: its DC term and its AC terms
/// (index `n = i · 5 + j`, 0 unused).
type Third = (f32, [f32; COMPONENTS * COMPONENTS]);

/// A texel's 13-bit AC fields, each holding the three thirds' quantised
/// term `n` (0 unused).
fn packed_ac(bytes: &[u8; BYTES]) -> [u32; COMPONENTS * COMPONENTS] {
    let mut packed = [0u32; COMPONENTS * COMPONENTS];
    for (n, p) in packed.iter_mut().enumerate().skip(1) {
        let bit = 13 * (n - 1);
        for b in 0..13 {
            *p |= u32::from(bytes[AC + (bit + b) / 8] >> ((bit + b) % 8) & 1) << b;
        }
    }
    packed
}

/// Third `c` of a texel whose AC fields are `packed`.
fn third_terms(bytes: &[u8; BYTES], packed: &[u32; COMPONENTS * COMPONENTS], c: usize) -> Third {
    let actual_max = (f32::from(bytes[3]) + 1.0) / 166.0;
    let mut ac = [0.0f32; COMPONENTS * COMPONENTS];
    for n in 1..COMPONENTS * COMPONENTS {
        let q = (packed[n] / 19u32.pow((THIRDS - 1 - c) as u32)) % 19;
        ac[n] = sign_pow((q as f32 - 9.0) / 9.0, 2.0) * actual_max;
    }
    (f32::from(bytes[c]) / 255.0, ac)
}

/// A third at the cosines `t` (time) and `d` (distance).
fn third_at(third: &Third, t: &[f32; COMPONENTS], d: &[f32; COMPONENTS]) -> f32 {
    let (dc, ac) = third;
    let mut v = *dc;
    for (n, a) in ac.iter().enumerate().skip(1) {
        let (i, j) = (n / COMPONENTS, n % COMPONENTS);
        v += a * t[i] * d[j];
    }
    v
}

/// A texel's three thirds, dequantised once (what `encode` evaluates at
/// every sample).
struct Thirds([Third; THIRDS]);

impl Thirds {
    fn of(bytes: &[u8; BYTES]) -> Self {
        let packed = packed_ac(bytes);
        Self(std::array::from_fn(|c| third_terms(bytes, &packed, c)))
    }

    /// Third `c` at the cosines `t` (time) and `d` (distance).
    fn at(&self, c: usize, t: &[f32; COMPONENTS], d: &[f32; COMPONENTS]) -> f32 {
        third_at(&self.0[c], t, d)
    }
}

/// The quantised thirds alone at time `tau` and shell `k`: only the third
/// that holds `tau` is dequantised.
fn base(bytes: &[u8; BYTES], times: usize, shells: usize, tau: f32, k: f32) -> f32 {
    let (c, x) = third(times, tau.rem_euclid(times as f32));
    let third = third_terms(bytes, &packed_ac(bytes), c);
    third_at(&third, &cosines(x), &cosines((k + 0.5) / shells as f32))
}

/// The value of an [`encode`]d texel at time `tau` and shell `k`,
/// clamped to [0, 1].
pub fn decode(bytes: &[u8; BYTES], times: usize, shells: usize, tau: f32, k: f32) -> f32 {
    let tau = tau.rem_euclid(times as f32);
    (base(bytes, times, shells, tau, k) + continuous::residuals(bytes, times, shells, tau, k))
        .clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_smooth_field_comes_back_within_blurhash_quantisation() {
        let (times, shells) = (255, 8);
        let field: Vec<f32> = (0..times * shells)
            .map(|s| {
                let (k, tau) = (s / times, s % times);
                0.5 - 0.04 * k as f32
                    + 0.1 * (tau as f32 / times as f32 * std::f32::consts::TAU).sin()
            })
            .collect();
        let bytes = encode(
            &field,
            times,
            shells,
            Encoding {
                bright_weight: 0.6,
                residuals: true,
            },
        );
        let worst = (0..times * shells)
            .map(|s| {
                (decode(
                    &bytes,
                    times,
                    shells,
                    (s % times) as f32,
                    (s / times) as f32,
                ) - field[s])
                    .abs()
            })
            .fold(0.0f32, f32::max);
        assert!(worst < 0.05, "{worst}");
    }
}
