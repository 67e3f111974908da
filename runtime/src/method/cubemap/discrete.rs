//! Kroon's *discrete radial distance* encoding of one texel's time curve
//! (Kroon 2023, §3.3.3–3.3.4, §4.1.1): the cyclic curve of `S_t` time
//! samples is cut at its 4 largest jumps (Algorithm 1), each segment is
//! fitted by a quadratic whose coefficients are bounded to [−4, 4] (a
//! bounded least-squares fit, not a clamp after the fit), and the texel
//! stores per segment 1 start byte and 3 coefficient bytes: 16 bytes.
//!
//! Choices the thesis leaves open, written down here:
//! * The polynomial's variable is the time since the segment's start as a
//!   fraction of the cycle, `x = (τ − start) / S_t` (so every segment
//!   "starts at the origin", and a coefficient bound of 4 means the same
//!   whatever the segment's length); the value is not shifted.
//! * Algorithm 1's windows are `V[i−1−k]` and `V[i+k]` for k = 0..=w,
//!   cyclically: the left window ends at i − 1 and the right one starts
//!   at i, so a jump between samples i − 1 and i peaks at i alone and the
//!   segment starts with the first sample after the jump (the thesis's
//!   sums both include `V[i]`, which ties i − 1 and i); candidates are taken in order of decreasing difference,
//!   ties by index, and a candidate closer than the minimum spacing to one
//!   already taken (cyclic distance) is skipped. When fewer than 4
//!   candidates qualify (a short curve), the last start repeats: an empty
//!   segment.
//! * A coefficient byte is `round((c + 4) · 255 / 8)`.

/// Segments per texel.
pub const SEGMENTS: usize = 4;
/// Algorithm 1's window (samples either side).
pub const WINDOW: usize = 5;
/// Algorithm 1's minimum spacing between breakpoints (samples).
pub const MIN_SPACING: usize = 32;
/// The coefficient bound.
pub const BOUND: f64 = 4.0;
/// Candidates [`breakpoints`] sorts at a time.
const CANDIDATE_RUN: usize = 64;

/// Algorithm 1's candidates: each sample `i` of a cyclic curve with the
/// difference between the windows before and from it.
fn jumps(values: &[f32]) -> Vec<(usize, f64)> {
    let n = values.len();
    let at = |i: isize| values[i.rem_euclid(n as isize) as usize] as f64;
    (0..n)
        .map(|i| {
            let (mut l, mut r) = (0.0, 0.0);
            for k in 0..=WINDOW as isize {
                l += at(i as isize - 1 - k);
                r += at(i as isize + k);
            }
            (i, (l - r).abs())
        })
        .collect()
}

/// The breakpoints of a cyclic curve (Algorithm 1), ascending.
pub fn breakpoints(values: &[f32]) -> [usize; SEGMENTS] {
    let n = values.len();
    if n == 0 {
        return [0; SEGMENTS];
    }
    let mut jumps = jumps(values);
    // Largest difference first, ties by index: a total order, so the
    // candidates come in one sequence however they are sorted.
    let order = |a: &(usize, f64), b: &(usize, f64)| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0));
    let cyclic = |a: usize, b: usize| {
        let d = a.abs_diff(b);
        d.min(n - d)
    };
    let spacing = MIN_SPACING.min(n / SEGMENTS).max(1);
    let mut found: Vec<usize> = Vec::with_capacity(SEGMENTS);
    let take = |candidates: &[(usize, f64)], found: &mut Vec<usize>| {
        for &(i, _) in candidates {
            if found.len() == SEGMENTS {
                break;
            }
            if found.iter().all(|&b| cyclic(i, b) >= spacing) {
                found.push(i);
            }
        }
    };
    // The candidates in order, a run at a time: a selection puts the
    // next run in front of the rest, and only the run is sorted. The
    // breakpoints are usually in the first run or two, so most of the
    // candidates are never sorted.
    let mut rest: &mut [(usize, f64)] = &mut jumps;
    while found.len() < SEGMENTS && !rest.is_empty() {
        let run = CANDIDATE_RUN.min(rest.len());
        if run < rest.len() {
            rest.select_nth_unstable_by(run - 1, order);
        }
        let (front, back) = std::mem::take(&mut rest).split_at_mut(run);
        front.sort_unstable_by(order);
        take(front, &mut found);
        rest = back;
    }
    found.sort_unstable();
    let mut out = [0; SEGMENTS];
    for (k, slot) in out.iter_mut().enumerate() {
        *slot = *found.get(k).or(found.last()).unwrap_or(&0);
    }
    out
}

/// The least-squares quadratic `c0 + c1·x + c2·x²` through `(x, y)` with
/// every coefficient in [−`BOUND`, `BOUND`]: the box-constrained
/// minimum, found exactly by trying every pattern of coefficients held at
/// a bound (27 for three) and keeping the best feasible one; the problem
/// is convex, so that is the constrained optimum.
pub fn bounded_quadratic(x: &[f64], y: &[f64]) -> [f64; 3] {
    // Normal equations: A = Σ φφᵀ, b = Σ φ y with φ = (1, x, x²).
    let mut a = [[0.0f64; 3]; 3];
    let mut b = [0.0f64; 3];
    for (&xi, &yi) in x.iter().zip(y) {
        let phi = [1.0, xi, xi * xi];
        for r in 0..3 {
            b[r] += phi[r] * yi;
            for c in 0..3 {
                a[r][c] += phi[r] * phi[c];
            }
        }
    }
    let objective = |c: &[f64; 3]| -> f64 {
        x.iter()
            .zip(y)
            .map(|(&xi, &yi)| {
                let e = c[0] + c[1] * xi + c[2] * xi * xi - yi;
                e * e
            })
            .sum()
    };
    let mut best: Option<([f64; 3], f64)> = None;
    for pattern in 0..27usize {
        // 0: free, 1: at −BOUND, 2: at +BOUND, per coefficient.
        let state = [pattern % 3, (pattern / 3) % 3, pattern / 9];
        let mut c = [0.0; 3];
        let free: Vec<usize> = (0..3).filter(|&k| state[k] == 0).collect();
        for k in 0..3 {
            c[k] = match state[k] {
                1 => -BOUND,
                2 => BOUND,
                _ => 0.0,
            };
        }
        if !free.is_empty() {
            // Solve the free block: A_ff c_f = b_f − A_fx c_x.
            let m = free.len();
            let mut mat = vec![vec![0.0; m + 1]; m];
            for (r, &fr) in free.iter().enumerate() {
                let mut rhs = b[fr];
                for k in 0..3 {
                    if state[k] != 0 {
                        rhs -= a[fr][k] * c[k];
                    }
                }
                for (q, &fq) in free.iter().enumerate() {
                    mat[r][q] = a[fr][fq];
                }
                mat[r][m] = rhs;
            }
            let Some(solution) = solve(mat) else {
                continue;
            };
            for (&k, v) in free.iter().zip(solution) {
                c[k] = v;
            }
        }
        if c.iter().any(|v| !v.is_finite() || v.abs() > BOUND + 1e-12) {
            continue;
        }
        let f = objective(&c);
        if best.is_none_or(|(_, bf)| f < bf - 1e-15) {
            best = Some((c, f));
        }
    }
    best.map_or([0.0; 3], |(c, _)| c)
}

/// Solves an augmented `m × (m+1)` system (m ≤ 3) with glam's f64
/// matrices; `None` when it is singular.
fn solve(m: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    use glam::{DMat2, DMat3, DVec2, DVec3};
    let n = m.len();
    let scale = m
        .iter()
        .flat_map(|r| r[..n].iter())
        .fold(0.0f64, |s, v| s.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    let singular = |det: f64| det.abs() <= 1e-12 * scale.powi(n as i32);
    match n {
        1 => (!singular(m[0][0])).then(|| vec![m[0][1] / m[0][0]]),
        2 => {
            let a = DMat2::from_cols(DVec2::new(m[0][0], m[1][0]), DVec2::new(m[0][1], m[1][1]));
            (!singular(a.determinant()))
                .then(|| a.inverse() * DVec2::new(m[0][2], m[1][2]))
                .map(|x| x.to_array().to_vec())
        }
        3 => {
            let a = DMat3::from_cols(
                DVec3::new(m[0][0], m[1][0], m[2][0]),
                DVec3::new(m[0][1], m[1][1], m[2][1]),
                DVec3::new(m[0][2], m[1][2], m[2][2]),
            );
            (!singular(a.determinant()))
                .then(|| a.inverse() * DVec3::new(m[0][3], m[1][3], m[2][3]))
                .map(|x| x.to_array().to_vec())
        }
        _ => None,
    }
}

/// The byte of a coefficient in [−4, 4].
pub fn coefficient_byte(c: f64) -> u8 {
    (((c.clamp(-BOUND, BOUND) + BOUND) * 255.0 / (2.0 * BOUND)).round()) as u8
}

/// The coefficient of a byte.
pub fn byte_coefficient(b: u8) -> f64 {
    f64::from(b) * (2.0 * BOUND) / 255.0 - BOUND
}

/// One texel's time curve (`S_t` ≤ 256 samples, cyclic) as 16 bytes:
/// per segment its start sample, then its three coefficient bytes.
pub fn encode(values: &[f32]) -> [u8; 16] {
    let n = values.len();
    let starts = breakpoints(values);
    let mut out = [0u8; 16];
    for s in 0..SEGMENTS {
        let start = starts[s];
        let end = if s + 1 < SEGMENTS {
            starts[s + 1]
        } else {
            starts[0] + n
        };
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for i in start..end {
            x.push((i - start) as f64 / n as f64);
            y.push(f64::from(values[i % n]));
        }
        let c = if x.is_empty() {
            [0.0; 3]
        } else {
            bounded_quadratic(&x, &y)
        };
        out[4 * s] = start as u8;
        for k in 0..3 {
            out[4 * s + 1 + k] = coefficient_byte(c[k]);
        }
    }
    out
}

/// The curve of [`encode`]d bytes at time `tau` ∈ [0, `samples`) (in time
/// samples; fractional times evaluate the segment's polynomial between
/// samples), clamped to [0, 1].
pub fn decode(bytes: &[u8; 16], samples: usize, tau: f32) -> f32 {
    let n = samples as f32;
    let tau = tau.rem_euclid(n);
    // The segment whose start is the latest at or before tau; before the
    // first start, the last segment (it wraps round).
    let mut seg = SEGMENTS - 1;
    for s in 0..SEGMENTS {
        if f32::from(bytes[4 * s]) <= tau {
            seg = s;
        }
    }
    let start = f32::from(bytes[4 * seg]);
    let x = f64::from((tau - start).rem_euclid(n) / n);
    let c = |k: usize| byte_coefficient(bytes[4 * seg + 1 + k]);
    (c(0) + c(1) * x + c(2) * x * x).clamp(0.0, 1.0) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cyclic curve of four quadratic pieces with jumps at 20, 90, 150
    /// and 220 of 255.
    fn pieces(n: usize) -> Vec<f32> {
        let cuts = [20usize, 90, 150, 220];
        (0..n)
            .map(|i| {
                let seg = cuts.iter().rposition(|&c| c <= i).unwrap_or(3);
                let start = cuts[seg];
                let x = ((i + n - start) % n) as f32 / n as f32;
                [
                    0.1 + 0.8 * x,
                    0.7 - 1.5 * x * x,
                    0.3 + 0.5 * x - x * x,
                    0.9 - 0.6 * x,
                ][seg]
            })
            .collect()
    }

    #[test]
    fn the_largest_jumps_are_found_cyclically_and_kept_apart() {
        let v = pieces(255);
        assert_eq!(breakpoints(&v), [20, 90, 150, 220]);
        // Rotating the curve rotates the breakpoints (a jump across the
        // end of the cycle is found like any other).
        let rotated: Vec<f32> = (0..255).map(|i| v[(i + 30) % 255]).collect();
        assert_eq!(breakpoints(&rotated), [60, 120, 190, 245]);
        // A flat curve still gives four starts, 32 apart or more.
        let b = breakpoints(&[0.5; 255]);
        for w in b.windows(2) {
            assert!(w[1] - w[0] >= MIN_SPACING, "{b:?}");
        }
    }

    /// Algorithm 1 as written: every candidate sorted, then the greedy
    /// pass.
    fn breakpoints_by_full_sort(values: &[f32]) -> Vec<usize> {
        let n = values.len();
        let mut jumps = jumps(values);
        jumps.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let spacing = MIN_SPACING.min(n / SEGMENTS).max(1);
        let mut found: Vec<usize> = Vec::new();
        for (i, _) in jumps {
            let apart = |b: &usize| i.abs_diff(*b).min(n - i.abs_diff(*b)) >= spacing;
            if found.len() < SEGMENTS && found.iter().all(apart) {
                found.push(i);
            }
        }
        found.sort_unstable();
        while found.len() < SEGMENTS {
            found.push(*found.last().unwrap_or(&0));
        }
        found
    }

    #[test]
    fn breakpoints_from_the_leading_candidates_equal_a_full_sort() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut random = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut curves: Vec<Vec<f32>> = Vec::new();
        for n in [3, 17, 64, 65, 100, 255, 256] {
            // Noise, steps, flat stretches (ties: the fallback past the
            // leading candidates) and a flat curve.
            curves.push((0..n).map(|_| random()).collect());
            curves.push((0..n).map(|i| ((i * 7 / n) as f32) * 0.1).collect());
            curves.push(
                (0..n)
                    .map(|i| if i % 50 < 3 { random() } else { 0.5 })
                    .collect(),
            );
            curves.push(vec![0.25; n]);
        }
        for curve in &curves {
            assert_eq!(
                breakpoints(curve).to_vec(),
                breakpoints_by_full_sort(curve),
                "{} samples",
                curve.len()
            );
        }
    }

    #[test]
    fn the_bounded_fit_is_least_squares_inside_the_box_and_optimal_on_it() {
        let x: Vec<f64> = (0..50).map(|i| i as f64 / 100.0).collect();
        let y: Vec<f64> = x.iter().map(|&t| 0.2 + 1.5 * t - 3.0 * t * t).collect();
        let c = bounded_quadratic(&x, &y);
        for (got, want) in c.iter().zip([0.2, 1.5, -3.0]) {
            assert!((got - want).abs() < 1e-9, "{c:?}");
        }
        // A curve that needs c2 = −20: the bound holds, and no feasible
        // coefficient vector on a grid around the answer does better.
        let y: Vec<f64> = x.iter().map(|&t| 1.0 - 20.0 * t * t).collect();
        let c = bounded_quadratic(&x, &y);
        assert!(c.iter().all(|v| v.abs() <= BOUND + 1e-12), "{c:?}");
        assert!((c[2] + BOUND).abs() < 1e-9, "c2 at its bound: {c:?}");
        let f = |c: [f64; 3]| -> f64 {
            x.iter()
                .zip(&y)
                .map(|(&t, &v)| (c[0] + c[1] * t + c[2] * t * t - v).powi(2))
                .sum()
        };
        let best = f(c);
        for d0 in [-0.05, 0.0, 0.05] {
            for d1 in [-0.05, 0.0, 0.05] {
                for d2 in [-0.05, 0.0, 0.05] {
                    let p = [c[0] + d0, c[1] + d1, c[2] + d2];
                    if p.iter().all(|v| v.abs() <= BOUND) {
                        assert!(f(p) >= best - 1e-12, "{p:?} beats {c:?}");
                    }
                }
            }
        }
        // Clamping the unconstrained fit would be worse than the bounded fit.
        let clamped = [c[0].clamp(-4.0, 4.0), 0.0f64.clamp(-4.0, 4.0), -4.0];
        assert!(best <= f(clamped));
    }

    #[test]
    fn a_piecewise_quadratic_curve_survives_within_quantisation() {
        let v = pieces(255);
        let bytes = encode(&v);
        assert_eq!(
            [bytes[0], bytes[4], bytes[8], bytes[12]],
            [20, 90, 150, 220]
        );
        // Each coefficient is off by at most half a step (8/255/2), and x
        // < 0.3 within a segment: the value by at most 0.016·(1 + x + x²).
        let worst = (0..255)
            .map(|i| (decode(&bytes, 255, i as f32) - v[i]).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.025, "worst {worst}");
    }

    #[test]
    fn coefficient_bytes_round_trip_within_half_a_step() {
        for c in [-4.0, -1.234, 0.0, 0.5, 3.99, 4.0] {
            let back = byte_coefficient(coefficient_byte(c));
            assert!((back - c).abs() <= 4.0 / 255.0 + 1e-12, "{c} → {back}");
        }
        assert_eq!(coefficient_byte(-4.0), 0);
        assert_eq!(coefficient_byte(4.0), 255);
    }
}
