//! vertex-linear (Kontkanen & Aila 2006): per-vertex AO as a linear
//! function of the joint angles, `a_v = jᵀ t_v` with `j = [angles…, 1]`,
//! fitted over reference poses by least squares (DESIGN §5).

use faer::Mat;
use half::f16;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cv::RidgeChoice;
use super::linalg::{RidgeSolver, SolveStats};
use crate::{
    pose_space::Range,
    trace::{AoBlock, AoRows},
};
use aobake_runtime::method::vertex::form::{Block, Coefficients, LinearForm, SparseForm};
pub use aobake_runtime::method::vertex::linear::{Features, VertexLinear};

/// The default ridge weight: on standardised angles it shrinks directions
/// of pose space with less than about 1/1000 of a typical angle's variance
/// (correlated angles in clip frames), and leaves well-spread random poses
/// all but untouched (a factor 1/(1 + 0.001)).
pub const DEFAULT_RIDGE: f64 = 1e-3;

/// Fitting options of vertex-linear.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinearOptions {
    /// Ridge (Tikhonov) weight λ on the coefficients of the standardised
    /// joint angles, per reference pose: minimises `(1/P)‖J T − A‖² +
    /// λ‖T‖²`. The constant column is not penalised. 0 gives the
    /// pseudo-inverse solution.
    pub ridge: f64,
    /// Coefficients of the standardised joint angles (AO change per
    /// standard deviation of the angle) with a magnitude below this are
    /// dropped and the rest stored sparse (CSR per vertex). 0 keeps the
    /// dense matrix.
    pub threshold: f32,
    /// Choose the ridge weight by cross-validation over clips: each
    /// candidate of [`RIDGE_CANDIDATES`] is fitted without the reference
    /// frames of one group of clips at a time and scored on them (up to
    /// [`super::cv::CV_FOLDS`] groups); the one with the least squared
    /// error wins. `ridge` is used when the reference frames come from
    /// fewer than two clips.
    pub ridge_cv: bool,
    /// Locality: with `on`, each vertex depends only on the parameters of
    /// the joints that skin it and their neighbours on the skeleton
    /// (`JointAngles::local_parameters`), the others' coefficients are
    /// zero and the model is stored sparse; `cv` lets the cross-validation
    /// over clips choose between that and every parameter (`off`).
    pub locality: Locality,
    /// Let the cross-validation over clips choose per vertex: its ridge
    /// weight, whether it is local (with `locality = cv`), or no pose
    /// dependence at all (the static average of the training clip frames),
    /// each vertex by its own error over the left-out clips.
    pub per_vertex: bool,
    /// What the model is linear in: each rotated joint's rotation vector
    /// (Kontkanen & Aila), or the 9 entries of its rotation matrix
    /// (smooth where rotation vectors wrap, and with the cosines an angle's
    /// even, symmetric effects).
    pub features: Features,
    /// With matrix features and a global model: how many principal
    /// directions of the standardised features the model is linear in, as
    /// a multiple of the number of joint angles (1: as many as rotation
    /// vectors have, so run-time cost and size stay Kontkanen & Aila's);
    /// 0 (the default) keeps every feature: with the eigen-AO basis a
    /// vertex costs the basis rows whatever the features, and the
    /// directions the projection dropped were ones a left-out clip moves
    /// (docs/methods/vertex.md).
    pub components: f32,
    /// Eigen-AO basis rows the fitted model is compressed into
    /// ([`super::basis`]): each vertex then costs `basis + 1` multiply-adds
    /// whatever the features (a model that costs no more is kept as
    /// fitted); 0 keeps the model as fitted. With `basis_cv`, the most.
    pub basis: usize,
    /// Basis entries (AO per standard deviation of a basis weight) below
    /// this are dropped and the rows stored sparse, so that a vertex reads
    /// only the rows that move it; 0 keeps them dense. With `basis_cv`,
    /// chosen.
    pub basis_threshold: f32,
    /// Choose the basis rows and threshold by cross-validation over clips
    /// ([`super::cv::choose_basis`]): of every rank up to `basis` and
    /// every threshold of [`super::cv::BASIS_THRESHOLDS`], the cheapest
    /// whose mean PSNR on left-out clips is within
    /// [`super::cv::BASIS_TOLERANCE_DB`] of the best; `basis` rows and
    /// `basis_threshold` when the reference frames come from fewer than
    /// two clips.
    pub basis_cv: bool,
}

/// The joint angles a vertex-linear model reads: their ranges (rotation
/// vectors first, 3 numbers per rotated joint, then translations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Angles<'a> {
    /// The range of every angle.
    pub ranges: &'a [Range],
    /// Rotated joints: the first `3 × rotations` angles.
    pub rotations: usize,
}

/// Whether vertex-linear's vertices see every parameter or only their
/// joints' neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Locality {
    /// Every parameter (Kontkanen & Aila).
    Off,
    /// The parameters of the joints near each vertex.
    On,
    /// Whichever scores better over left-out clips (`off` when the
    /// reference frames come from fewer than two clips).
    Cv,
}

impl Default for LinearOptions {
    fn default() -> Self {
        Self {
            ridge: DEFAULT_RIDGE,
            threshold: 0.0,
            ridge_cv: true,
            // With matrix features the cross-validation chose the global
            // model on every character measured (Fox, the Kenney
            // character, the milk truck, InterpolationTest,
            // RobotExpressive); the local candidates only cost fits.
            locality: Locality::Off,
            per_vertex: false,
            features: Features::Matrix,
            components: 0.0,
            // On unseen clips 32 rows held or raised the gains of the
            // full model (Fox +3.20 → +3.26 dB, Kenney +3.84 → +3.85) at
            // a third to four fifths of its run-time cost (docs/methods/vertex.md).
            basis: 32,
            basis_threshold: 0.0,
            basis_cv: true,
        }
    }
}

/// Columns of AO projected at a time in [`fit_many`]: `poses × 4096`
/// f64 (16 MB at 512 poses) instead of the whole block.
const PROJECT_COLUMNS: usize = 4096;

/// The ridge weights cross-validation chooses from.
pub const RIDGE_CANDIDATES: [f64; 6] = [1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0];

/// Chooses vertex-linear's ridge weight by leaving groups of clips out
/// (see [`super::cv::choose_by_clips`]); `None` when the rows come from
/// fewer than two clips.
pub fn choose_ridge(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    sources: &[super::cv::Source],
    options: &LinearOptions,
    local: Option<&[Vec<usize>]>,
) -> Option<RidgeChoice> {
    RidgeChoice::of(
        &RIDGE_CANDIDATES,
        &ridge_errors(poses, angles, ao, sources, options, local)?,
    )
}

/// Columns cross-validation fits and scores at a time
/// ([`super::cv::sse_by_clips_in_columns`]): the candidates' models over
/// every column of a texel block (hundreds of thousands) are never held
/// at once. A multiple of [`PROJECT_COLUMNS`], so that each column's
/// projection is computed as in one fit over every column (the same
/// bits); wider than most characters' vertices, whose fits take one
/// chunk.
pub(crate) const CV_COLUMNS: usize = 2 * PROJECT_COLUMNS;

/// The errors over left-out clips of every ridge weight of
/// [`RIDGE_CANDIDATES`] (see [`super::cv::sse_by_clips_in_columns`]),
/// what [`choose_ridge`] chooses by: `poses` and `sources` per row of
/// `ao` (read in place, not copied whole), a chunk of [`CV_COLUMNS`] at a
/// time.
pub(super) fn ridge_errors(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    sources: &[super::cv::Source],
    options: &LinearOptions,
    local: Option<&[Vec<usize>]>,
) -> Option<super::cv::ClipErrors> {
    super::cv::sse_by_clips_in_columns(
        sources,
        |i| ao.row(i),
        super::cv::Columns {
            count: ao.columns(),
            chunk: CV_COLUMNS,
        },
        RIDGE_CANDIDATES.len(),
        |train, columns| {
            let q: Vec<Vec<f32>> = train.iter().map(|&i| poses[i].clone()).collect();
            let block = ao
                .block()
                .select_columns(train.iter().map(|&i| ao.index(i)), columns.clone());
            fit_ridges(
                &q,
                angles,
                AoRows::all(&block),
                options,
                local.map(|l| &l[columns]),
            )
        },
        |model, i, _| model.evaluate(&poses[i]),
    )
}

/// One model per ridge weight of [`RIDGE_CANDIDATES`] (`None` where the
/// fit overflows), fitted to `poses` and `ao` (one row each), local with
/// `local`: one factorisation per design serves every candidate.
fn fit_ridges(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    options: &LinearOptions,
    local: Option<&[Vec<usize>]>,
) -> Vec<Option<VertexLinear>> {
    let scope = if local.is_some() {
        Scope::Local
    } else {
        Scope::Global
    };
    let models: Vec<Vec<Column>> = RIDGE_CANDIDATES
        .iter()
        .map(|&ridge| vec![Column { ridge, scope }; ao.columns()])
        .collect();
    let models: Vec<&[Column]> = models.iter().map(Vec::as_slice).collect();
    fit_many(poses, angles, ao, &models, local, options, None, false)
        .into_iter()
        .map(|fitted| fitted.ok().map(|(m, _)| m))
        .collect()
}

/// Chooses each vertex's [`Column`] by leaving groups of clips out (see
/// [`super::cv::sse_by_clips`]): every ridge of [`RIDGE_CANDIDATES`] in
/// every scope of `scopes` (`local` gives the local sets), and the
/// constant `baseline(rows)`,
/// the static average of the training rows `rows`. `None` when the rows
/// come from fewer than two clips.
#[allow(clippy::too_many_arguments)]
pub fn choose_columns(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    options: &LinearOptions,
    ao: &AoBlock,
    sources: &[super::cv::Source],
    scopes: &[Scope],
    local: Option<&[Vec<usize>]>,
    baseline: impl Fn(&[usize]) -> Vec<f32> + Sync,
) -> Option<Vec<Column>> {
    let scopes: Vec<Scope> = scopes
        .iter()
        .copied()
        .filter(|&s| s == Scope::Global || (s == Scope::Local && local.is_some()))
        .collect();
    let mut candidates: Vec<Column> = Vec::new();
    for &scope in &scopes {
        candidates.extend(
            RIDGE_CANDIDATES
                .iter()
                .map(|&ridge| Column { ridge, scope }),
        );
    }
    candidates.push(Column {
        ridge: 0.0,
        scope: Scope::Constant,
    });
    enum Fitted {
        Model(Box<VertexLinear>),
        Constant(Vec<f32>),
    }
    let errors = super::cv::sse_by_clips(
        sources,
        ao,
        candidates.len(),
        |train| {
            // The candidates' order: each scope's ridges, then the constant.
            let mut fitted: Vec<Option<Fitted>> = Vec::with_capacity(candidates.len());
            for &scope in &scopes {
                let sets = (scope == Scope::Local).then_some(local).flatten();
                let q: Vec<Vec<f32>> = train.iter().map(|&r| poses[r].clone()).collect();
                fitted.extend(
                    fit_ridges(&q, angles, AoRows::some(ao, train), options, sets)
                        .into_iter()
                        .map(|m| m.map(|m| Fitted::Model(Box::new(m)))),
                );
            }
            fitted.push(Some(Fitted::Constant(baseline(train))));
            fitted
        },
        |fitted, r| match fitted {
            Fitted::Model(m) => m.evaluate(&poses[r]),
            Fitted::Constant(c) => c.clone(),
        },
    )?;
    Some(
        (0..ao.vertices)
            .map(|i| {
                let best = (0..candidates.len())
                    .min_by(|&a, &b| errors.sse[a][i].total_cmp(&errors.sse[b][i]))
                    .unwrap_or(0);
                candidates[best]
            })
            .collect(),
    )
}

/// How many vertices took each way of `columns`, in the order first seen.
pub fn count_columns(columns: &[Column]) -> Vec<ColumnCount> {
    let mut counts: Vec<ColumnCount> = Vec::new();
    for &column in columns {
        match counts.iter_mut().find(|c| c.column == column) {
            Some(c) => c.vertices += 1,
            None => counts.push(ColumnCount {
                column,
                vertices: 1,
            }),
        }
    }
    counts
}

/// What the fit did, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearFitStats {
    /// The solve of the standardised joint-angle matrix.
    pub solve: SolveStats,
    /// Features that never moved over the reference poses (left out).
    pub constant_parameters: usize,
    /// RMSE over the training poses of the f64 fit, before f16 rounding
    /// and sparsification.
    pub training_rmse: f64,
    /// RMSE over the training poses of the stored model (f16, sparse).
    pub stored_training_rmse: f64,
    /// Coefficients kept / all coefficients.
    pub kept_fraction: f64,
    /// The ridge weight fitted with.
    #[serde(default)]
    pub ridge: f64,
    /// How cross-validation over clips chose it, when it did.
    #[serde(default)]
    pub ridge_cv: Option<super::cv::RidgeChoice>,
    /// Whether the model is local (each vertex on its joints' parameters).
    #[serde(default)]
    pub local: bool,
    /// With `per_vertex`: how many vertices took each choice.
    #[serde(default)]
    pub per_vertex: Option<Vec<ColumnCount>>,
    /// The eigen-AO compression, when there was one.
    #[serde(default)]
    pub basis: Option<super::basis::BasisStats>,
    /// How cross-validation over clips chose its rank, when it did.
    #[serde(default)]
    pub basis_cv: Option<super::cv::BasisChoice>,
    /// How cross-validation over clips chose the reference rows, when it
    /// did (`reference = cv`).
    #[serde(default)]
    pub reference: Option<super::cv::RowsChoice>,
}

/// How one vertex is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Column {
    /// Its ridge weight.
    pub ridge: f64,
    /// Which parameters it sees.
    pub scope: Scope,
}

/// Which parameters a vertex sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scope {
    /// Every parameter.
    Global,
    /// Its joints' neighbourhood (`JointAngles::local_parameters`).
    Local,
    /// None: a constant (the static average of the training clip frames).
    Constant,
}

/// How many vertices were fitted one way.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ColumnCount {
    /// The way.
    pub column: Column,
    /// Vertices fitted so.
    pub vertices: usize,
}

/// A fit whose coefficients f16 cannot hold.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the fit is ill-conditioned: a coefficient of {largest:e} does not fit in f16; use more reference poses than parameters ({parameters}) or a ridge weight"
)]
pub struct FitOverflow {
    /// The largest coefficient magnitude.
    pub largest: f64,
    /// The number of parameters.
    pub parameters: usize,
}

/// The largest value an f16 holds.
pub(crate) const F16_MAX: f64 = 65504.0;

/// Fits `T = J⁺A` over `poses` (one joint-angle vector per row of
/// `ao`), on standardised angles; the constant column, the mean AO, is
/// never penalised by the ridge. The solve goes through an SVD (see
/// [`ridge_lstsq`]).
pub fn fit(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    options: &LinearOptions,
    local: Option<&[Vec<usize>]>,
) -> Result<(VertexLinear, LinearFitStats), FitOverflow> {
    let column = Column {
        ridge: options.ridge,
        scope: if local.is_some() {
            Scope::Local
        } else {
            Scope::Global
        },
    };
    fit_columns(
        poses,
        angles,
        ao,
        &vec![column; ao.columns()],
        local,
        options,
        None,
    )
}

/// [`fit`] with every vertex fitted its own way
/// (`columns`, one per vertex): its ridge weight and which parameters
/// it sees. A [`Scope::Constant`] vertex gets `constants[vertex]`
/// (default: its mean over the poses) and no coefficients.
/// `options.ridge` is only reported.
pub fn fit_columns(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    columns: &[Column],
    local: Option<&[Vec<usize>]>,
    options: &LinearOptions,
    constants: Option<&[f32]>,
) -> Result<(VertexLinear, LinearFitStats), FitOverflow> {
    fit_many(
        poses,
        angles,
        ao,
        &[columns],
        local,
        options,
        constants,
        true,
    )
    .pop()
    .expect("one model")
}

/// [`fit_columns`] for several models at once (one per
/// entry of `models`): the features are built, standardised and
/// projected once, and each design matrix factorised once, whatever
/// the ridge weights (what cross-validation fits candidates with).
/// The models are projected only when none of them has a local
/// vertex. Without `training_errors` the statistics' training RMSEs
/// are NaN (not measured: cross-validation keeps only the models).
#[allow(clippy::too_many_arguments)]
pub fn fit_many(
    poses: &[Vec<f32>],
    angles: Angles<'_>,
    ao: AoRows<'_>,
    models: &[&[Column]],
    local: Option<&[Vec<usize>]>,
    options: &LinearOptions,
    constants: Option<&[f32]>,
    training_errors: bool,
) -> Vec<Result<(VertexLinear, LinearFitStats), FitOverflow>> {
    let p = poses.len();
    assert_eq!(p, ao.poses(), "one pose per AO row");
    assert!(p > 0, "at least one reference pose");
    assert!(
        poses.iter().all(|q| q.len() == angles.ranges.len()),
        "one range per angle"
    );
    let (features, rotations) = (options.features, angles.rotations);
    let raw = poses;
    let poses: Vec<Vec<f32>> = poses
        .iter()
        .map(|q| features.expand(q, rotations))
        .collect();
    let local: Option<Vec<Vec<usize>>> = local.map(|sets| {
        sets.iter()
            .map(|s| features.expand_indices(s, rotations))
            .collect()
    });
    let local = local.as_deref();
    let n = features.count(angles.ranges.len(), rotations);
    let v = ao.columns();
    let (mean_j, inv_std) = standardise(&poses, n);
    let mean_a = ao.mean();
    let js = Mat::from_fn(p, n, |r, k| {
        (f64::from(poses[r][k]) - mean_j[k]) * inv_std[k]
    });
    // Matrix features of a global model: projected onto their leading
    // principal directions (see `LinearOptions::components`).
    let components = (options.features == Features::Matrix
        && rotations > 0
        && options.components > 0.0
        && models
            .iter()
            .flat_map(|columns| columns.iter())
            .all(|c| c.scope != Scope::Local))
    .then(|| {
        let k = (options.components * angles.ranges.len() as f32).round() as usize;
        principal_directions(js.as_ref(), k.max(1))
    });
    let js = match &components {
        Some(d) => &js * d,
        None => js,
    };
    let local = if components.is_some() { None } else { local };
    let m = js.ncols();
    // The whole design's factorisation: the report's conditioning and
    // every global vertex's solve; one more per set of local
    // parameters.
    let whole = RidgeSolver::new(js.as_ref());
    let solve = whole.stats;
    let all: Vec<usize> = (0..m).collect();
    // Row-major k × n: row c is direction c.
    let projection: Option<Vec<f32>> = components.as_ref().map(|d| {
        (0..m)
            .flat_map(|c| (0..n).map(move |k| (k, c)))
            .map(|(k, c)| d[(k, c)] as f32)
            .collect()
    });
    // Per model, one solve per ridge weight and set of parameters, over
    // the vertices that share them.
    type Sets<'c> = std::collections::BTreeMap<(u64, &'c [usize]), Vec<usize>>;
    let model_sets: Vec<Sets<'_>> = models
        .iter()
        .map(|columns| {
            assert_eq!(columns.len(), v, "one column per vertex");
            let mut sets: Sets<'_> = Default::default();
            for (i, c) in columns.iter().enumerate() {
                let params = match c.scope {
                    Scope::Constant => continue,
                    Scope::Global => all.as_slice(),
                    Scope::Local => local.map_or(all.as_slice(), |l| l[i].as_slice()),
                };
                if !params.is_empty() {
                    sets.entry((c.ridge.to_bits(), params)).or_default().push(i);
                }
            }
            sets
        })
        .collect();
    // The factorisation of each set of parameters, and `Uᵀ Y` of each
    // (parameters, vertices) pair: what every ridge weight shares, so
    // cross-validation's candidates cost one projection, not one each.
    let mut keys: Vec<(&[usize], &[usize])> = model_sets
        .iter()
        .flat_map(|sets| {
            sets.iter()
                .map(|((_, params), vs)| (*params, vs.as_slice()))
        })
        .collect();
    keys.sort_unstable();
    keys.dedup();
    let mut designs: Vec<&[usize]> = keys.iter().map(|(params, _)| *params).collect();
    designs.dedup();
    let solvers: std::collections::BTreeMap<&[usize], RidgeSolver> = designs
        .par_iter()
        .filter(|params| params.len() != m)
        .map(|&params| {
            let d = Mat::from_fn(p, params.len(), |r, c| js[(r, params[c])]);
            (params, RidgeSolver::new(d.as_ref()))
        })
        .collect();
    let solver = |params: &[usize]| -> &RidgeSolver {
        if params.len() == m {
            &whole
        } else {
            &solvers[params]
        }
    };
    // `Uᵀ (A − mean)` a chunk of columns at a time, read from the f32
    // block: never a poses × columns f64 copy of it (a texel fit's block
    // is hundreds of MB; each copy doubled it). Each output column depends
    // only on its own column of A.
    let projections: std::collections::BTreeMap<(&[usize], &[usize]), Mat<f64>> = keys
        .par_iter()
        .map(|&(params, vertices)| {
            let solver = solver(params);
            let mut out: Option<Mat<f64>> = None;
            for (k, chunk) in vertices.chunks(PROJECT_COLUMNS).enumerate() {
                let y = Mat::from_fn(p, chunk.len(), |r, c| {
                    f64::from(ao.row(r)[chunk[c]]) - mean_a[chunk[c]]
                });
                let uty = solver.project(y.as_ref());
                let out = out.get_or_insert_with(|| Mat::zeros(uty.nrows(), vertices.len()));
                out.as_mut()
                    .submatrix_mut(0, k * PROJECT_COLUMNS, uty.nrows(), chunk.len())
                    .copy_from(&uty);
            }
            ((params, vertices), out.expect("every set has a vertex"))
        })
        .collect();
    let shared = Shared {
        raw,
        ao,
        angles,
        options,
        js: &js,
        mean_a: &mean_a,
        mean_j: &mean_j,
        inv_std: &inv_std,
        projection: projection.as_deref(),
        solve,
        training_errors,
    };
    // The models side by side, each on its own thread.
    models
        .par_iter()
        .zip(&model_sets)
        .map(|(columns, sets)| {
            let mut t = Mat::zeros(m, v);
            for (&(ridge, params), vertices) in sets {
                let lambda = f64::from_bits(ridge) * p as f64;
                let uty = &projections[&(params, vertices.as_slice())];
                let x = solver(params).solve_projected(uty, lambda);
                for (c, &i) in vertices.iter().enumerate() {
                    for (row, &k) in params.iter().enumerate() {
                        t[(k, i)] = x[(row, c)];
                    }
                }
            }
            shared.finish(columns, &t, constants)
        })
        .collect()
}

/// The first `k` (at most) right singular vectors of `d` with non-zero
/// singular values, as columns.
fn principal_directions(d: faer::MatRef<'_, f64>, k: usize) -> Mat<f64> {
    if d.nrows() == 0 || d.ncols() == 0 {
        return Mat::zeros(d.ncols(), 0);
    }
    let svd = d.thin_svd().expect("SVD of a finite matrix converges");
    let s = svd.S().column_vector();
    let s_max = s.iter().copied().fold(0.0f64, f64::max);
    let rank = s
        .iter()
        .take_while(|&&x| x > super::linalg::RANK_TOLERANCE * s_max && x > 0.0)
        .count();
    let k = k.min(rank);
    Mat::from_fn(d.ncols(), k, |r, c| svd.V()[(r, c)])
}

/// What every model of one [`fit_many`] shares: the
/// standardised design and what it was built from.
struct Shared<'a> {
    /// The reference poses' joint angles, as given.
    raw: &'a [Vec<f32>],
    ao: AoRows<'a>,
    angles: Angles<'a>,
    options: &'a LinearOptions,
    /// Standardised (and maybe projected) features: poses × parameters.
    js: &'a Mat<f64>,
    /// Mean AO per vertex.
    mean_a: &'a [f64],
    /// Mean and inverse standard deviation of each feature.
    mean_j: &'a [f64],
    inv_std: &'a [f64],
    /// Row-major parameters × features, when projected.
    projection: Option<&'a [f32]>,
    solve: SolveStats,
    training_errors: bool,
}

impl Shared<'_> {
    /// A model from its coefficients `t` (parameters × vertices): rounded
    /// to f16 (refused when one overflows), stored sparse when a
    /// threshold or locality zeroes some, with its statistics.
    fn finish(
        &self,
        columns: &[Column],
        t: &Mat<f64>,
        constants: Option<&[f32]>,
    ) -> Result<(VertexLinear, LinearFitStats), FitOverflow> {
        let (p, v, m) = (self.raw.len(), self.ao.columns(), t.nrows());
        let (features, rotations) = (self.options.features, self.angles.rotations);
        let mut mean_a = self.mean_a.to_vec();
        if let Some(constants) = constants {
            for (i, c) in columns.iter().enumerate() {
                if c.scope == Scope::Constant {
                    mean_a[i] = f64::from(constants[i]);
                }
            }
        }
        let largest = (0..m)
            .flat_map(|k| (0..v).map(move |i| (k, i)))
            .map(|(k, i)| t[(k, i)].abs())
            .fold(0.0f64, f64::max);
        if largest.is_nan() || largest > F16_MAX {
            return Err(FitOverflow {
                largest,
                parameters: m,
            });
        }
        let mut coefficients = Vec::with_capacity((m + 1) * v);
        for k in 0..m {
            coefficients.extend((0..v).map(|i| f16::from_f64(t[(k, i)])));
        }
        coefficients.extend(mean_a.iter().map(|&c| f16::from_f64(c)));
        let block = Block {
            rows: m + 1,
            columns: v,
            coefficients,
            map: None,
        };
        let uniform = columns.iter().all(|c| c.scope == Scope::Global);
        let threshold = match (!uniform, self.options.threshold > 0.0) {
            (_, true) => self.options.threshold,
            // Locality or constant vertices: the coefficients outside a
            // vertex's set are zero.
            (true, false) => f32::MIN_POSITIVE,
            (false, false) => 0.0,
        };
        let (stored, kept_fraction) = if threshold > 0.0 {
            let sparse = SparseForm::from_dense(&block, v, threshold, &[m]);
            let kept = sparse.values.len() as f64 / ((m + 1) * v).max(1) as f64;
            (Coefficients::Sparse(sparse), kept)
        } else {
            (
                Coefficients::Dense(LinearForm {
                    vertices: v,
                    blocks: vec![block],
                }),
                1.0,
            )
        };
        let model = VertexLinear {
            parameters: m,
            projection: self.projection.map(<[f32]>::to_vec),
            features,
            rotations,
            mean: self.mean_j.iter().map(|&x| x as f32).collect(),
            inv_std: self.inv_std.iter().map(|&x| x as f32).collect(),
            ranges: self.angles.ranges.to_vec(),
            coefficients: stored,
            basis: None,
        };
        // The f64 fit's predictions in one product, not a dot product
        // per pose and vertex. Cross-validation's candidates skip this
        // (their statistics are not kept).
        let (mut exact, mut rounded) = (f64::NAN, f64::NAN);
        if self.training_errors {
            let fitted = self.js * t;
            (exact, rounded) = (0.0, 0.0);
            for (r, q) in self.raw.iter().enumerate() {
                let predicted = model.evaluate(q);
                for (i, (&truth, &pred)) in self.ao.row(r).iter().zip(&predicted).enumerate() {
                    let f = mean_a[i] + fitted[(r, i)];
                    exact += (f - f64::from(truth)).powi(2);
                    rounded += (f64::from(pred) - f64::from(truth)).powi(2);
                }
            }
        }
        let count = (p * v).max(1) as f64;
        let stats = LinearFitStats {
            solve: self.solve,
            constant_parameters: self.inv_std.iter().filter(|&&s| s == 0.0).count(),
            training_rmse: (exact / count).sqrt(),
            stored_training_rmse: (rounded / count).sqrt(),
            kept_fraction,
            ridge: self.options.ridge,
            ridge_cv: None,
            local: columns.iter().any(|c| c.scope == Scope::Local),
            per_vertex: None,
            basis: None,
            basis_cv: None,
            reference: None,
        };
        Ok((model, stats))
    }
}

/// The mean and inverse standard deviation of each of `n` features over
/// `poses` (0 for a feature that barely moves: it is constant).
fn standardise(poses: &[Vec<f32>], n: usize) -> (Vec<f64>, Vec<f64>) {
    let p = poses.len() as f64;
    let mean: Vec<f64> = (0..n)
        .map(|k| poses.iter().map(|q| f64::from(q[k])).sum::<f64>() / p)
        .collect();
    let inv_std = (0..n)
        .map(|k| {
            let var = poses
                .iter()
                .map(|q| (f64::from(q[k]) - mean[k]).powi(2))
                .sum::<f64>()
                / p;
            // An angle that moved less than this (radians) is constant.
            if var.sqrt() > 1e-6 {
                1.0 / var.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    (mean, inv_std)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt as _, SeedableRng as _};
    use rand_chacha::ChaCha8Rng;

    const WIDE: [Range; 3] = [Range {
        min: -2.0,
        max: 2.0,
    }; 3];

    /// Three translations (no rotated joints), each in [-2, 2].
    fn wide() -> Angles<'static> {
        Angles {
            ranges: &WIDE,
            rotations: 0,
        }
    }

    /// AO that is exactly linear in 3 parameters, plus a vertex that
    /// ignores them.
    fn linear_data(poses: usize) -> (Vec<Vec<f32>>, AoBlock) {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let q: Vec<Vec<f32>> = (0..poses)
            .map(|_| (0..3).map(|_| rng.random_range(-1.0f32..1.0)).collect())
            .collect();
        let mut values = Vec::new();
        for x in &q {
            values.push(0.5 + 0.1 * x[0] - 0.05 * x[2]);
            values.push(0.25);
            values.push(0.3 + 0.2 * x[1]);
        }
        (
            q,
            AoBlock {
                vertices: 3,
                values,
            },
        )
    }

    #[test]
    fn recovers_linear_ao_on_unseen_poses() {
        let (q, ao) = linear_data(40);
        let exact = LinearOptions {
            ridge: 0.0,
            features: Features::RotationVector,
            ..LinearOptions::default()
        };
        let (model, stats) = fit(&q, wide(), AoRows::all(&ao), &exact, None).unwrap();
        assert_eq!(stats.solve.rank, 3);
        assert!(stats.training_rmse < 1e-6, "{stats:?}");
        assert!(
            stats.stored_training_rmse < 1e-3,
            "f16 rounding only: {stats:?}"
        );
        let ao = model.evaluate(&[0.5, -0.5, 1.0]);
        let want = [0.5 + 0.05 - 0.05, 0.25, 0.3 - 0.1];
        for (a, b) in ao.iter().zip(want) {
            assert!((a - b).abs() < 1e-3, "{ao:?}");
        }
        assert_eq!(model.multiply_adds(), 4.0);
        // Outside its range an angle is clamped: 3 counts as 2.
        assert_eq!(
            model.evaluate(&[3.0, 0.0, 0.0]),
            model.evaluate(&[2.0, 0.0, 0.0])
        );
        assert_eq!(model.bytes(), 2 * 4 * 3 + 8 * 3);
    }

    #[test]
    fn threshold_drops_small_coefficients_and_ridge_shrinks() {
        let (q, ao) = linear_data(40);
        let options = LinearOptions {
            threshold: 0.01,
            ..LinearOptions::default()
        };
        let (model, stats) = fit(&q, wide(), AoRows::all(&ao), &options, None).unwrap();
        // 3 of the 9 angle coefficients are non-zero, plus 3 constants.
        let Coefficients::Sparse(s) = &model.coefficients else {
            panic!("sparse expected")
        };
        assert_eq!(s.values.len(), 3 + 3);
        assert!((stats.kept_fraction - 0.5).abs() < 1e-9);
        assert!(stats.stored_training_rmse < 1e-3);
        let (ridged, rs) = fit(
            &q,
            wide(),
            AoRows::all(&ao),
            &LinearOptions {
                ridge: 1.0,
                ..LinearOptions::default()
            },
            None,
        )
        .unwrap();
        assert!(rs.training_rmse > 1e-3, "ridge trades fit for smaller T");
        let slope = ridged.evaluate(&[1.0, 0.0, 0.0])[0] - ridged.evaluate(&[0.0, 0.0, 0.0])[0];
        assert!(slope > 0.0 && slope < 0.1, "{slope}");
    }

    #[test]
    fn matrix_features_are_the_rotation_matrix_and_follow_a_whole_turn() {
        // One joint turned by θ about x, then one translation (3 angles).
        let f = |theta: f32| Features::Matrix.expand(&[theta, 0.0, 0.0, 0.5, 0.0, -1.0], 1);
        assert_eq!(Features::Matrix.count(6, 1), 12);
        let a = f(0.7);
        assert_eq!(a.len(), 12);
        // Column-major R − I: R[1][1] − 1 = cos θ − 1, R[1][2] = sin θ.
        assert!((a[4] - (0.7f32.cos() - 1.0)).abs() < 1e-6, "{a:?}");
        assert!((a[5] - 0.7f32.sin()).abs() < 1e-6, "{a:?}");
        assert_eq!(&a[9..], &[0.5, 0.0, -1.0]);
        // Rotation vectors wrap at π; the matrix is continuous through it.
        let (below, above) = (f(3.1), f(3.1 - std::f32::consts::TAU));
        assert!(below.iter().zip(&above).all(|(x, y)| (x - y).abs() < 1e-5));
        // Angle 4 (x of the translation) drives feature 9; angle 1 (the
        // joint) drives the joint's 9.
        assert_eq!(
            Features::Matrix.expand_indices(&[1, 4], 1),
            vec![0, 1, 2, 3, 4, 5, 6, 7, 8, 10]
        );
        assert_eq!(
            Features::RotationVector.expand_indices(&[1, 4], 1),
            vec![1, 4]
        );
    }
}
