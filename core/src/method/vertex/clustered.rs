//! vertex-clustered (Kirk & Arikan 2007): poses as handle vectors,
//! k-means into `m` pose clusters, PCA to `n` dimensions per cluster, a
//! linear model per vertex (or per vertex cluster) per pose cluster on
//! mean-subtracted AO, blended with moving least squares (DESIGN §5).
//!
//! One choice beyond the paper, on by default and measured in the issue
//! note: [`Centering::Cluster`] adds a constant per vertex and pose
//! cluster, so each cluster's model is centred on the cluster's own mean
//! AO rather than the global one (Eq. 1 subtracts the global mean only,
//! which leaves every cluster's prediction at its centre pose equal to the
//! global mean). [`Centering::Global`] is the paper's Eq. 1 exactly.

use faer::Mat;
use half::f16;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::kmeans::kmeans;
use super::linalg::{principal_axes, ridge_lstsq};
use super::linear::{F16_MAX, FitOverflow, VertexLinear};
use crate::{pose_space::JointAngles, trace::AoBlock};
pub use aobake_runtime::method::vertex::clustered::{
    Centering, LinearBase, MIN_BLEND_WEIGHT, PoseCluster, VertexClustered,
};
use aobake_runtime::method::vertex::form::{Block, Coefficients, LinearForm};

/// Fitting options of vertex-clustered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClusteredOptions {
    /// m: pose clusters (k-means over handle vectors).
    pub pose_clusters: usize,
    /// n: PCA dimensions per pose cluster.
    pub dimensions: usize,
    /// Vertex clusters per pose cluster (greedy hierarchical clustering,
    /// Kirk & Arikan §3.2); 0 stores one coefficient vector per vertex.
    pub vertex_clusters: usize,
    /// Splitting stops early once every vertex lies within this RMS
    /// distance (AO per pose) of its cluster's centre.
    pub vertex_tolerance: f32,
    /// α: the MLS blend falloff ‖h − h̄_j‖^(−α) (Eq. 5).
    pub alpha: f32,
    /// Global (the paper) or per-cluster centring.
    pub centering: Centering,
    /// Ridge weight per pose on each cluster's fit (0: pseudo-inverse); it
    /// shrinks the per-cluster constant row too, towards the global mean.
    pub ridge: f64,
    /// At run time each whitened PCA coordinate is clamped to ±this many
    /// standard deviations of the cluster's training poses (0: no clamp),
    /// so a pose far from every cluster does not extrapolate a linear
    /// model without bound (the paper's "blotchy patches").
    pub clamp: f32,
    /// Choose the ridge weight by cross-validation over clips (as
    /// vertex-linear does, from [`super::linear::RIDGE_CANDIDATES`]);
    /// `ridge` is used when it is off or the reference frames come from
    /// fewer than two clips. Off by default: on unseen clips it measured
    /// +0.3 dB on Fox but −1.6 dB on the Kenney character (docs/methods/vertex.md).
    pub ridge_cv: bool,
    /// Choose `clamp` by the same cross-validation over clips, among
    /// [`CLAMP_CANDIDATES`]. Off by default: on unseen clips it measured
    /// +0.31 dB on Fox and −0.36 dB on the Kenney character (whose worst
    /// fold it lifted from −4.57 to −2.81 dB).
    pub clamp_cv: bool,
    /// What the pose clusters' models add to: the global mean AO (`mean`,
    /// the paper), or a vertex-linear model of the joint angles (`linear`,
    /// global and dense, with vertex-linear's options), fitted first; the
    /// clusters then model what it leaves. The linear model's block takes
    /// the mean's place in the linear form.
    pub base: Base,
    /// Eigen-AO basis rows the whole fitted model (base and every pose
    /// cluster) is compressed into ([`super::basis`]); 0 keeps it as
    /// fitted. With `basis_cv`, the most.
    pub basis: usize,
    /// Basis entries below this are dropped, as vertex-linear's
    /// `basis_threshold`.
    pub basis_threshold: f32,
    /// Choose the basis rows and threshold by cross-validation over clips,
    /// as vertex-linear does ([`super::cv::choose_basis`]).
    pub basis_cv: bool,
}

/// What vertex-clustered's pose clusters add to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// The global mean AO (Kirk & Arikan).
    Mean,
    /// A vertex-linear model (the default in [`ClusteredOptions`]: on
    /// unseen clips it lifted Fox from +0.1 to +3.2 dB over the static
    /// average, see docs/methods/vertex.md).
    Linear,
}

impl Default for ClusteredOptions {
    fn default() -> Self {
        Self {
            pose_clusters: 10,
            dimensions: 10,
            vertex_clusters: 0,
            vertex_tolerance: 0.0,
            alpha: 10.0,
            centering: Centering::Cluster,
            ridge: super::linear::DEFAULT_RIDGE,
            clamp: 3.0,
            ridge_cv: false,
            clamp_cv: false,
            base: Base::Linear,
            // One basis for the base and every cluster: the per-vertex
            // cost no longer grows with the clusters MLS blends (Fox: 144
            // → 33 multiply-adds, unseen clips +3.23 → +3.43 dB; docs/methods/vertex.md).
            basis: 32,
            basis_threshold: 0.0,
            basis_cv: true,
        }
    }
}

/// The run-time clamps (standard deviations) cross-validation chooses
/// from.
pub const CLAMP_CANDIDATES: [f64; 5] = [0.5, 1.0, 2.0, 3.0, 5.0];

/// A pose cluster's PCA keeps the directions whose spread is at least
/// this fraction of its largest. Whitening divides by the spread, so a
/// direction the cluster's handles barely move along (10⁻⁸ of the
/// largest) turned a slerp's last bits into 2.5·10⁻⁴ of AO (RiggedFigure
/// between keys, against 2·10⁻⁶ without it).
const SPREAD_TOLERANCE: f64 = 1e-4;

/// The whitened principal `axes` (rows, largest spread first, each scaled
/// by one over its spread) whose spread is at least [`SPREAD_TOLERANCE`]
/// of the first's.
fn spread_axes(axes: Mat<f64>) -> Mat<f64> {
    let scale = |i: usize| axes.row(i).norm_l2();
    let keep = (0..axes.nrows())
        .take_while(|&i| scale(i) * SPREAD_TOLERANCE <= scale(0))
        .count();
    Mat::from_fn(keep, axes.ncols(), |i, c| axes[(i, c)])
}

/// What the fit did, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClusteredFitStats {
    /// Training poses per pose cluster.
    pub cluster_sizes: Vec<usize>,
    /// PCA dimensions with variance per cluster (≤ n).
    pub cluster_ranks: Vec<usize>,
    /// Vertex clusters per pose cluster (the vertex count without spatial
    /// compression).
    pub vertex_clusters: Vec<usize>,
    /// RMSE of the stored model over the training poses.
    pub stored_training_rmse: f64,
    /// How cross-validation over clips chose the ridge weight, when it
    /// did.
    #[serde(default)]
    pub ridge_cv: Option<super::cv::RidgeChoice>,
    /// How it chose the clamp, when it did.
    #[serde(default)]
    pub clamp_cv: Option<super::cv::RidgeChoice>,
    /// The linear base's fit, when there is one.
    #[serde(default)]
    pub base: Option<super::linear::LinearFitStats>,
    /// The eigen-AO compression, when there was one.
    #[serde(default)]
    pub basis: Option<super::basis::BasisStats>,
    /// How cross-validation over clips chose its rank, when it did.
    #[serde(default)]
    pub basis_cv: Option<super::cv::BasisChoice>,
    /// How cross-validation over clips chose the reference rows, when it
    /// did (`reference = cv`; the linear base and the clusters use the
    /// same rows).
    #[serde(default)]
    pub reference: Option<super::cv::RowsChoice>,
}

/// Fits vertex-clustered to `handles` (one handle vector per row of `ao`).
/// `seed` seeds k-means++.
pub fn fit(
    handles: &[Vec<f32>],
    ao: &AoBlock,
    options: &ClusteredOptions,
    seed: u64,
) -> Result<(VertexClustered, ClusteredFitStats), FitOverflow> {
    let p = handles.len();
    assert_eq!(p, ao.poses(), "one pose per AO row");
    assert!(p > 0, "at least one reference pose");
    let dim = handles[0].len();
    let v = ao.vertices;
    let n = options.dimensions;
    let offset = options.centering == Centering::Cluster;
    let rows = n + usize::from(offset);
    let m = options.pose_clusters.clamp(1, p);

    let points: Vec<f64> = handles.iter().flatten().map(|&x| f64::from(x)).collect();
    let km = kmeans(&points, dim, m, seed);
    let mean = ao.mean();

    let mut blocks = vec![Block {
        rows: 1,
        columns: v,
        coefficients: mean.iter().map(|&x| f16::from_f64(x)).collect(),
        map: None,
    }];
    let mut clusters = Vec::with_capacity(m);
    let mut stats = ClusteredFitStats {
        cluster_sizes: Vec::with_capacity(m),
        cluster_ranks: Vec::with_capacity(m),
        vertex_clusters: Vec::with_capacity(m),
        stored_training_rmse: 0.0,
        ridge_cv: None,
        clamp_cv: None,
        base: None,
        basis: None,
        basis_cv: None,
        reference: None,
    };
    // The pose clusters are fitted side by side, each on its own
    // thread, and gathered in their order.
    let fitted: Vec<Result<(Block, PoseCluster, usize, usize), FitOverflow>> = (0..m)
        .into_par_iter()
        .map(|j| {
            let members: Vec<usize> = (0..p).filter(|&r| km.assignment[r] == j).collect();
            let k = members.len();
            let center = &km.centers[j * dim..(j + 1) * dim];
            let xc = Mat::from_fn(k, dim, |r, c| points[members[r] * dim + c] - center[c]);
            let axes = principal_axes(xc.as_ref(), n);
            let axes = spread_axes(axes);
            let rank = axes.nrows();
            let scores = &xc * axes.transpose();
            let q = Mat::from_fn(k, rank + usize::from(offset), |r, c| {
                if c < rank { scores[(r, c)] } else { 1.0 }
            });
            let y = Mat::from_fn(k, v, |r, i| f64::from(ao.row(members[r])[i]) - mean[i]);
            let (targets, map) = if options.vertex_clusters > 0 && options.vertex_clusters < v {
                let groups = vertex_clusters(
                    y.as_ref(),
                    options.vertex_clusters,
                    f64::from(options.vertex_tolerance),
                );
                let count = groups.count;
                let mut sums = Mat::<f64>::zeros(k, count);
                let mut sizes = vec![0usize; count];
                for (i, &g) in groups.map.iter().enumerate() {
                    sizes[g as usize] += 1;
                    for r in 0..k {
                        sums[(r, g as usize)] += y[(r, i)];
                    }
                }
                let means = Mat::from_fn(k, count, |r, g| sums[(r, g)] / sizes[g] as f64);
                (means, Some(groups.map))
            } else {
                (y, None)
            };
            let (x, _) = ridge_lstsq(q.as_ref(), targets.as_ref(), options.ridge * k as f64);
            let largest = x.norm_max();
            if largest.is_nan() || largest > F16_MAX {
                return Err(FitOverflow {
                    largest,
                    parameters: x.nrows(),
                });
            }
            let columns = targets.ncols();
            // Rows past the cluster's rank stay zero; the constant, if
            // any, is always the last row.
            let mut coefficients = vec![f16::ZERO; rows * columns];
            for r in 0..x.nrows() {
                let dst = if r < rank { r } else { n };
                for c in 0..columns {
                    coefficients[dst * columns + c] = f16::from_f64(x[(r, c)]);
                }
            }
            let mut axes_f32 = vec![0.0f32; n * dim];
            for r in 0..rank {
                for c in 0..dim {
                    axes_f32[r * dim + c] = axes[(r, c)] as f32;
                }
            }
            Ok((
                Block {
                    rows,
                    columns,
                    coefficients,
                    map,
                },
                PoseCluster {
                    center: center.iter().map(|&x| x as f32).collect(),
                    axes: axes_f32,
                },
                rank,
                k,
            ))
        })
        .collect();
    for fit in fitted {
        // The first cluster that overflows is the one reported.
        let (block, cluster, rank, k) = fit?;
        stats.cluster_sizes.push(k);
        stats.cluster_ranks.push(rank);
        stats.vertex_clusters.push(block.columns);
        blocks.push(block);
        clusters.push(cluster);
    }
    let model = VertexClustered {
        handles: dim,
        dimensions: n,
        alpha: options.alpha,
        centering: options.centering,
        clamp: options.clamp,
        clusters,
        form: Coefficients::Dense(LinearForm {
            vertices: v,
            blocks,
        }),
        base: None,
        basis: None,
    };
    let mut se = 0.0f64;
    for (r, h) in handles.iter().enumerate() {
        let predicted = model.evaluate(h);
        se += predicted
            .iter()
            .zip(ao.row(r))
            .map(|(&a, &b)| f64::from(a - b).powi(2))
            .sum::<f64>();
    }
    stats.stored_training_rmse = (se / (p * v).max(1) as f64).sqrt();
    Ok((model, stats))
}

/// Puts a fitted linear base under a model fitted to what the base
/// leaves: block 0 (the leftover's mean) is added to the base's
/// constant row and replaced by the base's block.
pub fn with_base(
    mut model: VertexClustered,
    joint_angles: JointAngles,
    base: VertexLinear,
) -> VertexClustered {
    let Coefficients::Dense(form) = &base.coefficients else {
        panic!("a linear base is dense")
    };
    let Coefficients::Dense(own) = &mut model.form else {
        panic!("a base goes under a model as fitted, before a basis")
    };
    let mut block = form.blocks[0].clone();
    let last = (block.rows - 1) * block.columns;
    for (c, m) in block.coefficients[last..]
        .iter_mut()
        .zip(&own.blocks[0].coefficients)
    {
        *c = f16::from_f32(c.to_f32() + m.to_f32());
    }
    own.blocks[0] = block;
    let weights = VertexLinear {
        coefficients: Coefficients::Dense(LinearForm {
            vertices: own.vertices,
            blocks: Vec::new(),
        }),
        ..base
    };
    model.base = Some(Box::new(LinearBase {
        joint_angles,
        weights,
    }));
    model
}

/// Vertex clusters of one pose cluster.
struct VertexGroups {
    count: usize,
    map: Vec<u32>,
}

/// Kirk & Arikan's greedy hierarchical vertex clustering (§3.2): features
/// are the columns of `y` (each vertex's mean-subtracted AO over the
/// cluster's poses). Start with one cluster; repeatedly take the cluster
/// whose farthest vertex is farthest from its centre, make that vertex a
/// new centre, and reassign the cluster's vertices to the nearer of the
/// two; stop at `max` clusters or when every vertex is within `tolerance`
/// (RMS per pose) of its centre. Deterministic: ties go to the lower index.
fn vertex_clusters(y: faer::MatRef<'_, f64>, max: usize, tolerance: f64) -> VertexGroups {
    let (k, v) = (y.nrows(), y.ncols());
    let limit2 = tolerance * tolerance * k as f64;
    let dist2 = |i: usize, c: &[f64]| (0..k).map(|r| (y[(r, i)] - c[r]).powi(2)).sum::<f64>();
    let centroid = |members: &[usize]| -> Vec<f64> {
        let mut c = vec![0.0; k];
        for &i in members {
            for (r, x) in c.iter_mut().enumerate() {
                *x += y[(r, i)];
            }
        }
        c.iter_mut().for_each(|x| *x /= members.len().max(1) as f64);
        c
    };
    // (members, centre, farthest member, its squared distance)
    struct Group {
        members: Vec<usize>,
        center: Vec<f64>,
        far: usize,
        far2: f64,
    }
    let make =
        |members: Vec<usize>| -> Group {
            let center = centroid(&members);
            let (far, far2) = members.iter().map(|&i| (i, dist2(i, &center))).fold(
                (members[0], -1.0),
                |best, x| if x.1 > best.1 { x } else { best },
            );
            Group {
                members,
                center,
                far,
                far2,
            }
        };
    let mut groups = vec![make((0..v).collect())];
    while groups.len() < max {
        let (g, _) = groups.iter().enumerate().fold((0, -1.0), |best, (i, gr)| {
            if gr.far2 > best.1 { (i, gr.far2) } else { best }
        });
        if groups[g].far2 <= limit2 || groups[g].members.len() < 2 {
            break;
        }
        let old = std::mem::replace(
            &mut groups[g],
            Group {
                members: Vec::new(),
                center: Vec::new(),
                far: 0,
                far2: 0.0,
            },
        );
        let seed: Vec<f64> = (0..k).map(|r| y[(r, old.far)]).collect();
        let (mut stay, mut go) = (Vec::new(), Vec::new());
        for &i in &old.members {
            if i == old.far || dist2(i, &seed) < dist2(i, &old.center) {
                go.push(i);
            } else {
                stay.push(i);
            }
        }
        if stay.is_empty() {
            // Every member is nearer the far vertex: split it off alone.
            stay = go.iter().copied().filter(|&i| i != old.far).collect();
            go = vec![old.far];
        }
        groups[g] = make(stay);
        groups.push(make(go));
    }
    let mut map = vec![0u32; v];
    for (c, gr) in groups.iter().enumerate() {
        for &i in &gr.members {
            map[i] = u32::try_from(c).expect("fewer clusters than u32::MAX");
        }
    }
    VertexGroups {
        count: groups.len(),
        map,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two well-separated families of poses on a line, AO piecewise linear
    /// in the pose: one model per family fits it exactly.
    fn two_families() -> (Vec<Vec<f32>>, AoBlock) {
        let mut h = Vec::new();
        let mut values = Vec::new();
        for i in 0..20 {
            let t = i as f32 / 19.0;
            for (base, slope) in [(0.0f32, 0.4f32), (10.0, -0.3)] {
                let x = base + t;
                h.push(vec![x, 2.0 * x]);
                values.extend([
                    0.4 + slope * t,
                    0.5,
                    0.5 + 0.5 * slope * t,
                    0.41 + slope * t,
                ]);
            }
        }
        (
            h,
            AoBlock {
                vertices: 4,
                values,
            },
        )
    }

    #[test]
    fn directions_the_handles_barely_move_along_are_not_whitened() {
        // Spread 1 along x, 1e-6 along y (a last bit's wobble), 1e-2
        // along z.
        let rows = 40;
        let xc = Mat::from_fn(rows, 3, |r, c| {
            let t = (r as f64 * 0.7).sin();
            let u = (r as f64 * 1.3).cos();
            match c {
                0 => t,
                1 => 1e-6 * u,
                _ => 1e-2 * (r as f64 * 2.1).sin(),
            }
        });
        let axes = principal_axes(xc.as_ref(), 3);
        assert_eq!(axes.nrows(), 3, "PCA alone keeps all three");
        let kept = spread_axes(axes);
        assert_eq!(kept.nrows(), 2, "the wobble's direction is dropped");
        // The kept ones are x and z, whitened (one over their spread).
        assert!(kept[(0, 0)].abs() > 0.99 * kept.row(0).norm_l2());
        assert!(kept[(1, 2)].abs() > 0.99 * kept.row(1).norm_l2());
        assert!(kept.row(1).norm_l2() > 50.0 * kept.row(0).norm_l2());
    }

    #[test]
    fn piecewise_linear_ao_is_fitted_per_cluster() {
        let (h, ao) = two_families();
        let options = ClusteredOptions {
            pose_clusters: 2,
            dimensions: 1,
            ..ClusteredOptions::default()
        };
        let (model, stats) = fit(&h, &ao, &options, 1).unwrap();
        assert_eq!(stats.cluster_sizes, vec![20, 20]);
        assert_eq!(stats.cluster_ranks, vec![1, 1]);
        assert!(stats.stored_training_rmse < 2e-3, "{stats:?}");
        // An unseen pose in the second family.
        let t = 0.55f32;
        let x = 10.0 + t;
        let got = model.evaluate(&[x, 2.0 * x]);
        let want = [0.4 - 0.3 * t, 0.5, 0.5 - 0.15 * t, 0.41 - 0.3 * t];
        for (a, b) in got.iter().zip(want) {
            assert!((a - b).abs() < 2e-3, "{got:?} vs {want:?}");
        }
        // The paper's global centring cannot fit both offsets with one
        // slope per cluster through the global mean.
        let global = ClusteredOptions {
            centering: Centering::Global,
            ..options
        };
        let (_, g) = fit(&h, &ao, &global, 1).unwrap();
        assert!(g.stored_training_rmse > 10.0 * stats.stored_training_rmse);
    }

    #[test]
    fn vertex_clusters_share_coefficients() {
        let (h, ao) = two_families();
        let options = ClusteredOptions {
            pose_clusters: 2,
            dimensions: 1,
            vertex_clusters: 3,
            ..ClusteredOptions::default()
        };
        let (model, stats) = fit(&h, &ao, &options, 1).unwrap();
        assert_eq!(stats.vertex_clusters, vec![3, 3]);
        // Vertices 0 and 3 move together (offset 0.01): one cluster.
        let Coefficients::Dense(form) = &model.form else {
            panic!("dense as fitted")
        };
        for block in &form.blocks[1..] {
            let map = block.map.as_ref().unwrap();
            assert_eq!(map[0], map[3]);
            assert_ne!(map[0], map[1]);
            assert_ne!(map[1], map[2]);
        }
        assert!(stats.stored_training_rmse < 0.01, "{stats:?}");
        let one = ClusteredOptions {
            vertex_clusters: 1,
            ..options
        };
        let (_, coarse) = fit(&h, &ao, &one, 1).unwrap();
        assert!(coarse.stored_training_rmse > stats.stored_training_rmse);
    }

    #[test]
    fn blend_weights_are_normalised_and_local() {
        let (h, ao) = two_families();
        let options = ClusteredOptions {
            pose_clusters: 2,
            dimensions: 1,
            ..ClusteredOptions::default()
        };
        let (model, _) = fit(&h, &ao, &options, 1).unwrap();
        let w = model.blend_weights(&[10.5, 21.0]);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(w.iter().filter(|&&x| x > 0.0).count(), 1, "{w:?}");
        let c = model.clusters[0].center.clone();
        let on = model.blend_weights(&c);
        assert_eq!(on[0], 1.0);
        // Halfway between the centres both count equally.
        let mid: Vec<f32> = model.clusters[0]
            .center
            .iter()
            .zip(&model.clusters[1].center)
            .map(|(a, b)| 0.5 * (a + b))
            .collect();
        let half = model.blend_weights(&mid);
        assert!((half[0] - 0.5).abs() < 1e-6, "{half:?}");
    }
}
