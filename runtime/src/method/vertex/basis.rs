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
        assert_eq!(weights.len(), self.inputs, "one weight per input");
        let mut out: Vec<f64> = self.offset.iter().map(|&o| -f64::from(o)).collect();
        for (row, &w) in self.mix.chunks_exact(self.rank).zip(weights) {
            if w != 0.0 {
                out.iter_mut()
                    .zip(row)
                    .for_each(|(o, &m)| *o += w * f64::from(m));
            }
        }
        out.push(1.0);
        out.into_iter().map(|x| x as f32).collect()
    }

    /// Bytes of the mix and offsets (f32).
    pub fn bytes(&self) -> usize {
        4 * (self.mix.len() + self.offset.len())
    }
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
