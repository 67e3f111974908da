//! Seeded k-means with k-means++ seeding (Arthur & Vassilvitskii 2007),
//! for Kirk & Arikan's pose clusters: tens to thousands of points of a few
//! hundred dimensions, where a deterministic result matters more than
//! speed. (linfa-clustering does the same over ndarray, a second matrix
//! stack beside faer for forty lines of Lloyd iterations.)

use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;

/// At most this many Lloyd iterations; they stop earlier once no point
/// changes cluster.
const MAX_ITERATIONS: usize = 200;

/// Clusters of the rows of a row-major `points` matrix (`dim` columns).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct KMeans {
    /// Row-major `k × dim` centres.
    pub centers: Vec<f64>,
    /// Cluster of each point.
    pub assignment: Vec<usize>,
}

fn distance2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// `k` clusters (k ≤ number of points) of `points`, seeded. Every cluster
/// keeps at least one point: an emptied cluster takes the point farthest
/// from its centre.
pub(crate) fn kmeans(points: &[f64], dim: usize, k: usize, seed: u64) -> KMeans {
    let n = points.len() / dim;
    assert!(k >= 1 && k <= n, "1 ≤ k ≤ points");
    let row = |i: usize| &points[i * dim..(i + 1) * dim];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);

    // k-means++: each next centre is a point drawn with probability
    // proportional to its squared distance from the nearest centre so far.
    let mut centers = Vec::with_capacity(k * dim);
    centers.extend_from_slice(row(rng.random_range(0..n)));
    let mut nearest: Vec<f64> = (0..n).map(|i| distance2(row(i), &centers[..dim])).collect();
    while centers.len() < k * dim {
        let total: f64 = nearest.iter().sum();
        let pick = if total > 0.0 {
            let mut u = rng.random_range(0.0..total);
            nearest
                .iter()
                .position(|&d| {
                    u -= d;
                    u < 0.0
                })
                .unwrap_or_else(|| nearest.iter().rposition(|&d| d > 0.0).unwrap_or(0))
        } else {
            // Every point coincides with a centre: duplicates are all left.
            rng.random_range(0..n)
        };
        let c = centers.len();
        centers.extend_from_slice(row(pick));
        for (i, d) in nearest.iter_mut().enumerate() {
            *d = d.min(distance2(row(i), &centers[c..c + dim]));
        }
    }

    let mut assignment = vec![usize::MAX; n];
    for _ in 0..MAX_ITERATIONS {
        let mut changed = false;
        for (i, a) in assignment.iter_mut().enumerate() {
            let best = (0..k)
                .map(|c| (distance2(row(i), &centers[c * dim..(c + 1) * dim]), c))
                .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
                .map(|(_, c)| c)
                .expect("k ≥ 1");
            changed |= *a != best;
            *a = best;
        }
        if !changed {
            break;
        }
        let mut counts = vec![0usize; k];
        centers.iter_mut().for_each(|x| *x = 0.0);
        for (i, &a) in assignment.iter().enumerate() {
            counts[a] += 1;
            for (c, x) in centers[a * dim..(a + 1) * dim].iter_mut().zip(row(i)) {
                *c += x;
            }
        }
        for c in 0..k {
            if counts[c] > 0 {
                let inv = 1.0 / counts[c] as f64;
                centers[c * dim..(c + 1) * dim]
                    .iter_mut()
                    .for_each(|x| *x *= inv);
            } else {
                // Re-seed an empty cluster with the point farthest from
                // its own centre (taking it from a cluster of two or more).
                let far = (0..n)
                    .filter(|&i| counts[assignment[i]] > 1)
                    .map(|i| {
                        let a = assignment[i];
                        (distance2(row(i), &centers[a * dim..(a + 1) * dim]), i)
                    })
                    .max_by(|x, y| x.0.total_cmp(&y.0).then(y.1.cmp(&x.1)))
                    .map(|(_, i)| i)
                    .expect("n ≥ k, so some cluster has two points");
                counts[assignment[far]] -= 1;
                assignment[far] = c;
                counts[c] = 1;
                centers[c * dim..(c + 1) * dim].copy_from_slice(row(far));
            }
        }
    }
    KMeans {
        centers,
        assignment,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_separated_blobs_and_is_seeded() {
        // Three tight blobs in 2-D, 20 points each.
        let mut pts = Vec::new();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for (cx, cy) in [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)] {
            for _ in 0..20 {
                pts.push(cx + rng.random_range(-0.5..0.5));
                pts.push(cy + rng.random_range(-0.5..0.5));
            }
        }
        let km = kmeans(&pts, 2, 3, 7);
        for blob in 0..3 {
            let a = &km.assignment[blob * 20..(blob + 1) * 20];
            assert!(a.iter().all(|&c| c == a[0]), "blob {blob} split: {a:?}");
        }
        let mut firsts: Vec<usize> = (0..3).map(|b| km.assignment[b * 20]).collect();
        firsts.sort_unstable();
        assert_eq!(firsts, vec![0, 1, 2]);
        assert_eq!(kmeans(&pts, 2, 3, 7), km, "same seed, same clusters");
    }

    #[test]
    fn k_equal_to_n_and_duplicates_leave_no_cluster_empty() {
        let pts = [1.0, 1.0, 1.0, 1.0, 5.0, 5.0];
        let km = kmeans(&pts, 1, 6, 0);
        let mut seen = km.assignment.clone();
        seen.sort_unstable();
        assert_eq!(seen, vec![0, 1, 2, 3, 4, 5]);
    }
}
