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
            let best = nearest_center(row(i), &centers, dim);
            changed |= *a != best;
            *a = best;
        }
        if !changed {
            break;
        }
        let mut counts = means(points, dim, &assignment, &mut centers);
        // Re-seed each empty cluster with the point farthest from its own
        // centre, taken from a cluster of two or more; every centre is a
        // mean at this point, so the distances are the real ones.
        for c in 0..k {
            if counts[c] > 0 {
                continue;
            }
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
    // The centres returned are the means of the final clusters, whatever
    // ended the loop.
    means(points, dim, &assignment, &mut centers);
    KMeans {
        centers,
        assignment,
    }
}

/// The centre nearest to `point` (the lower index on ties).
fn nearest_center(point: &[f64], centers: &[f64], dim: usize) -> usize {
    (0..centers.len() / dim)
        .map(|c| (distance2(point, &centers[c * dim..(c + 1) * dim]), c))
        .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
        .map(|(_, c)| c)
        .expect("k ≥ 1")
}

/// Sets each non-empty cluster's centre to the mean of its points (empty
/// ones keep theirs) and returns the cluster sizes.
fn means(points: &[f64], dim: usize, assignment: &[usize], centers: &mut [f64]) -> Vec<usize> {
    let k = centers.len() / dim;
    let mut counts = vec![0usize; k];
    let mut sums = vec![0.0f64; centers.len()];
    for (i, &a) in assignment.iter().enumerate() {
        counts[a] += 1;
        for (s, x) in sums[a * dim..(a + 1) * dim]
            .iter_mut()
            .zip(&points[i * dim..(i + 1) * dim])
        {
            *s += x;
        }
    }
    for c in 0..k {
        if counts[c] > 0 {
            let inv = 1.0 / counts[c] as f64;
            for (x, s) in centers[c * dim..(c + 1) * dim]
                .iter_mut()
                .zip(&sums[c * dim..(c + 1) * dim])
            {
                *x = s * inv;
            }
        }
    }
    counts
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
        // Centres are the means of their points.
        for c in 0..3 {
            let members: Vec<usize> = (0..60).filter(|&i| km.assignment[i] == c).collect();
            for d in 0..2 {
                let mean =
                    members.iter().map(|&i| pts[2 * i + d]).sum::<f64>() / members.len() as f64;
                assert!((km.centers[2 * c + d] - mean).abs() < 1e-12);
            }
        }
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
