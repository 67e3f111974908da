//! The eigen-AO basis's per-pose step (aobake-core's `basis` module finds
//! the basis when it bakes): a vertex model's per-pose weights `w` in,
//! `w' = Mᵀ w − o` and a 1 out, the weights of the basis rows `[σ R; c]`
//! that the model's one coefficient block then holds (`docs/asset-format.md`).

/// The per-pose step of an eigen-AO model: its `inputs` weights in, `rank`
/// basis weights (and a 1) out.
#[derive(Debug, Clone, PartialEq)]
pub struct Basis {
    /// Weights the model computes per pose (W).
    pub inputs: usize,
    /// Basis rows (r).
    pub rank: usize,
    /// `M`: `inputs × rank`, row-major.
    pub mix: Vec<f32>,
    /// `o`: one per basis row.
    pub offset: Vec<f32>,
}

impl Basis {
    /// The basis weights of one pose's model weights, then a 1 (the mean's
    /// row).
    pub fn apply(&self, weights: &[f32]) -> Vec<f32> {
        let weights: Vec<f64> = weights.iter().map(|&w| f64::from(w)).collect();
        self.apply_f64(&weights)
    }

    /// [`Basis::apply`] in double precision, rounded once at the end.
    pub fn apply_f64(&self, weights: &[f64]) -> Vec<f32> {
        let mut out = vec![0.0; self.rank + 1];
        self.apply_f64_into(weights, &mut Vec::new(), &mut out);
        out
    }

    /// [`Basis::apply_f64`] into `out` (`rank + 1` values), summing in
    /// `sums`: nothing is allocated once `sums` has held a pose's.
    pub fn apply_f64_into(&self, weights: &[f64], sums: &mut Vec<f64>, out: &mut [f32]) {
        assert_eq!(weights.len(), self.inputs, "one weight per input");
        assert_eq!(out.len(), self.rank + 1, "one value per basis row and a 1");
        sums.clear();
        sums.extend(self.offset.iter().map(|&o| -f64::from(o)));
        for (row, &w) in self.mix.chunks_exact(self.rank).zip(weights) {
            if w != 0.0 {
                sums.iter_mut()
                    .zip(row)
                    .for_each(|(o, &m)| *o += w * f64::from(m));
            }
        }
        sums.push(1.0);
        out.iter_mut()
            .zip(sums.iter())
            .for_each(|(o, &x)| *o = x as f32);
    }

    /// Bytes of the mix and offsets (f32).
    pub fn bytes(&self) -> usize {
        4 * (self.mix.len() + self.offset.len())
    }
}

/// A model's unrounded weights `w` as the weights of its form: through
/// the basis when it has one, else rounded, into `out` (`sums` as for
/// [`Basis::apply_f64_into`]).
pub(crate) fn finish(w: &[f64], basis: Option<&Basis>, sums: &mut Vec<f64>, out: &mut [f32]) {
    match basis {
        Some(b) => b.apply_f64_into(w, sums, out),
        None => {
            assert_eq!(out.len(), w.len(), "one value per weight");
            out.iter_mut().zip(w).for_each(|(o, &x)| *o = x as f32);
        }
    }
}

/// [`finish`] into a new vector.
pub(crate) fn finished(w: &[f64], basis: Option<&Basis>) -> Vec<f32> {
    let mut out = vec![0.0; basis.map_or(w.len(), |b| b.rank + 1)];
    finish(w, basis, &mut Vec::new(), &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apply_is_the_mix_times_the_weights_less_the_offsets_then_a_one() {
        let basis = Basis {
            inputs: 2,
            rank: 2,
            // Row per input: input 0 → [1, 2], input 1 → [3, 4].
            mix: vec![1.0, 2.0, 3.0, 4.0],
            offset: vec![0.5, 1.0],
        };
        assert_eq!(basis.apply(&[1.0, 2.0]), [6.5, 9.0, 1.0]);
        assert_eq!(basis.apply(&[0.0, 1.0]), [2.5, 3.0, 1.0]);
        assert_eq!(basis.bytes(), 4 * 6);
    }
}
