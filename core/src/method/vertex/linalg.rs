//! Least squares and PCA through faer's SVD, the two solves every vertex
//! method needs. Everything runs sequentially (faer is built without
//! rayon), so a fit gives the same bits on every run of one build.

use faer::{Mat, MatRef};

/// How a least-squares fit went, for the report.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveStats {
    /// Singular values kept (the numerical rank of the design matrix).
    pub rank: usize,
    /// Columns of the design matrix.
    pub columns: usize,
    /// Largest over smallest kept singular value.
    pub condition: f64,
}

/// Singular values below this fraction of the largest are treated as zero
/// (rank deficiency: a parameter that never moves, two that always move
/// together).
pub(crate) const RANK_TOLERANCE: f64 = 1e-9;

/// `X = argmin ‖D X − Y‖² + λ‖X‖²` for a `p × k` design `D` and `p × v`
/// targets `Y`, by the thin SVD `D = U S Vᵀ`: `X = V diag(s / (s² + λ)) Uᵀ
/// Y`, with singular values under [`RANK_TOLERANCE`] of the largest
/// dropped. No normal equations and no explicit inverse: with λ = 0 this is
/// the pseudo-inverse solution, the minimum-norm one when `D` is rank
/// deficient.
pub(crate) fn ridge_lstsq(
    d: MatRef<'_, f64>,
    y: MatRef<'_, f64>,
    lambda: f64,
) -> (Mat<f64>, SolveStats) {
    let solver = RidgeSolver::new(d);
    (solver.solve(y, lambda), solver.stats)
}

/// The SVD of a design matrix, kept to solve [`ridge_lstsq`] for many
/// targets and ridge weights without factorising it again.
pub(crate) struct RidgeSolver {
    u: Mat<f64>,
    s: Vec<f64>,
    v: Mat<f64>,
    /// The design's rank and conditioning.
    pub(crate) stats: SolveStats,
}

impl RidgeSolver {
    /// Factorises `d` (`p × k`).
    pub(crate) fn new(d: MatRef<'_, f64>) -> Self {
        let k = d.ncols();
        if d.nrows() == 0 || k == 0 {
            return Self {
                u: Mat::zeros(d.nrows(), 0),
                s: Vec::new(),
                v: Mat::zeros(k, 0),
                stats: SolveStats {
                    rank: 0,
                    columns: k,
                    condition: 1.0,
                },
            };
        }
        let svd = d.thin_svd().expect("SVD of a finite matrix converges");
        let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
        let s_max = s.first().copied().unwrap_or(0.0);
        // Singular values come sorted, largest first: the kept ones are a
        // prefix.
        let rank = s
            .iter()
            .take_while(|&&x| x > RANK_TOLERANCE * s_max && x > 0.0)
            .count();
        Self {
            u: svd.U().to_owned(),
            v: svd.V().to_owned(),
            stats: SolveStats {
                rank,
                columns: k,
                condition: if rank == 0 { 1.0 } else { s_max / s[rank - 1] },
            },
            s,
        }
    }

    /// `X = V diag(s / (s² + λ)) Uᵀ Y` over the kept singular values.
    pub(crate) fn solve(&self, y: MatRef<'_, f64>, lambda: f64) -> Mat<f64> {
        self.solve_projected(&self.project(y), lambda)
    }

    /// `Uᵀ Y`: the part of [`RidgeSolver::solve`] that does not depend on
    /// λ (and the costly one: design rows × columns × targets), to be
    /// shared by every ridge weight.
    pub(crate) fn project(&self, y: MatRef<'_, f64>) -> Mat<f64> {
        self.u.transpose() * y
    }

    /// [`RidgeSolver::solve`] given `uty` = [`RidgeSolver::project`]`(Y)`:
    /// the same bits.
    pub(crate) fn solve_projected(&self, uty: &Mat<f64>, lambda: f64) -> Mat<f64> {
        let rank = self.stats.rank;
        let y_cols = uty.ncols();
        let filtered = Mat::from_fn(self.s.len(), y_cols, |i, c| {
            if i < rank {
                uty[(i, c)] * self.s[i] / (self.s[i] * self.s[i] + lambda)
            } else {
                0.0
            }
        });
        &self.v * &filtered
    }
}

/// The top `n` principal axes of the rows of a centred `p × d` matrix, as
/// the rows of an `n' × d` matrix (n' ≤ n: axes without variance are
/// dropped), each divided by the standard deviation along it, so that the
/// projections of the rows have unit variance (whitened: coefficients
/// fitted on them are in AO units whatever the model's length unit). Each
/// axis's sign is fixed (its largest component positive) so the result
/// does not depend on the SVD's arbitrary signs.
pub(crate) fn principal_axes(centred: MatRef<'_, f64>, n: usize) -> Mat<f64> {
    principal_axes_of_factor(centred, centred.nrows(), n)
}

/// [`principal_axes`] of a centred `rows × d` matrix `Q m` given only `m`
/// (`Q` with orthonormal columns): `m` has the same singular values and
/// right singular vectors, and may be far smaller.
pub(crate) fn principal_axes_of_factor(m: MatRef<'_, f64>, rows: usize, n: usize) -> Mat<f64> {
    let d = m.ncols();
    if rows == 0 || m.nrows() == 0 || d == 0 || n == 0 {
        return Mat::zeros(0, d);
    }
    let svd = m.thin_svd().expect("SVD of a finite matrix converges");
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    let s_max = s.first().copied().unwrap_or(0.0);
    let keep = s
        .iter()
        .take(n)
        .take_while(|&&x| x > RANK_TOLERANCE * s_max && x > 0.0)
        .count();
    let v = svd.V();
    let rows = rows as f64;
    // Per axis: its sign (largest component positive) over the standard
    // deviation of the projections along it.
    let scale: Vec<f64> = (0..keep)
        .map(|i| {
            let col = v.col(i);
            let big = (0..d)
                .max_by(|&a, &b| col[a].abs().total_cmp(&col[b].abs()).then(b.cmp(&a)))
                .expect("d > 0");
            col[big].signum() / (s[i] / rows.sqrt())
        })
        .collect();
    Mat::from_fn(keep, d, |i, j| v[(j, i)] * scale[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_linear_map_and_handles_rank_deficiency() {
        // y = 2 a − b + 3, with a duplicated column (rank deficient).
        let rows = 20;
        let d = Mat::from_fn(rows, 4, |i, j| match j {
            0 => (i as f64 * 0.37).sin(),
            1 => (i as f64 * 0.91).cos(),
            2 => (i as f64 * 0.37).sin(),
            _ => 1.0,
        });
        let y = Mat::from_fn(rows, 1, |i, _| 2.0 * d[(i, 0)] - d[(i, 1)] + 3.0);
        let (x, stats) = ridge_lstsq(d.as_ref(), y.as_ref(), 0.0);
        assert_eq!(stats.rank, 3);
        // Minimum norm splits the duplicated column's weight evenly.
        assert!((x[(0, 0)] - 1.0).abs() < 1e-9 && (x[(2, 0)] - 1.0).abs() < 1e-9);
        assert!((x[(1, 0)] + 1.0).abs() < 1e-9 && (x[(3, 0)] - 3.0).abs() < 1e-9);
        // Ridge shrinks.
        let (xr, _) = ridge_lstsq(d.as_ref(), y.as_ref(), 10.0);
        let norm = |m: &Mat<f64>| m.norm_l2();
        assert!(norm(&xr) < norm(&x));
    }

    #[test]
    fn principal_axes_of_a_line() {
        let p = Mat::from_fn(10, 3, |i, j| (i as f64 - 4.5) * [1.0, -2.0, 0.0][j]);
        let axes = principal_axes(p.as_ref(), 2);
        assert_eq!(axes.nrows(), 1, "one axis has variance");
        // Along (−1, 2, 0)/√5, largest component positive.
        assert!((axes[(0, 0)] * 2.0 + axes[(0, 1)]).abs() < 1e-12);
        assert!(axes[(0, 1)] > 0.0 && axes[(0, 2)] == 0.0);
        // Whitened: the projections have unit variance.
        let proj = &p * axes.transpose();
        let var = (0..10).map(|i| proj[(i, 0)].powi(2)).sum::<f64>() / 10.0;
        assert!((var - 1.0).abs() < 1e-12, "{var}");
    }
}
