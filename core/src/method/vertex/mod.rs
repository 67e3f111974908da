//! The per-vertex methods (DESIGN §5): fitting, run-time evaluation, and
//! their place in the asset container.
//!
//! * [`StaticAverage`]: the baseline, mean AO over the reference poses.
//! * [`VertexLinear`]: Kontkanen & Aila 2006, linear in the joint angles.
//! * [`VertexClustered`]: Kirk & Arikan 2007, locally linear in PCA-reduced
//!   handle positions, blended by moving least squares.
//!
//! All three evaluate as a [`LinearForm`] (or a [`SparseForm`]): per pose a
//! few weights computed from the pose, per vertex a dot product with f16
//! coefficients. [`Model`] ties a fitted model to the pose features it
//! reads (joint angles or handles) and to the asset container.

mod average;
mod basis;
mod clustered;
pub mod cv;
mod kmeans;
mod linalg;
mod linear;

pub use aobake_runtime::method::vertex::codec::{
    AssetHeader, AssetHeaderFields, BaseLayout, Layout, PrimitiveSpan, UNITS,
};
pub use aobake_runtime::method::vertex::form::{
    self, Block, Coefficients, FormRef, LinearForm, SparseForm,
};
pub use average::{StaticAverage, fit as fit_static_average};
pub use basis::{Basis, BasisStats};
pub use clustered::{
    Base, CLAMP_CANDIDATES, Centering, ClusteredFitStats, ClusteredOptions, LinearBase,
    MIN_BLEND_WEIGHT, PoseCluster, VertexClustered, fit as fit_vertex_clustered, with_base,
};
pub use cv::{BasisCandidate, BasisChoice, Rows, RowsChoice, Source};
pub use linalg::SolveStats;
pub use linear::{
    Angles, Column, ColumnCount, DEFAULT_RIDGE, Features, FitOverflow, LinearFitStats,
    LinearOptions, Locality, RIDGE_CANDIDATES, Scope, VertexLinear, choose_columns, choose_ridge,
    count_columns, fit as fit_vertex_linear, fit_columns as fit_linear_columns,
    fit_many as fit_linear_many,
};

use aobake_runtime::Method;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{
    pose_space::{Handles, JointAngles},
    rig::{pose::Pose, skeleton::Skeleton},
    trace::{AoBlock, AoRows},
};

pub use aobake_runtime::method::vertex::{ALGORITHM_VERSION, Model, VertexAo};

/// Whether the model can evaluate poses of `character`: the same vertex
/// count, and every node it reads exists. (An asset read from a file is
/// self-consistent after [`Model::from_container`]; this checks it
/// against the character it is used with.)
pub fn check_character(model: &Model, character: &crate::Character) -> Result<(), String> {
    if character.vertex_count() != model.vertices() {
        return Err(format!(
            "the character has {} vertices but the asset was baked for {} vertices",
            character.vertex_count(),
            model.vertices()
        ));
    }
    let nodes = character.skeleton.nodes.len();
    let ok = match model {
        Model::StaticAverage(_) => true,
        Model::VertexLinear(layout, _) => layout.nodes().all(|n| n < nodes),
        Model::VertexClustered(handles, m) => {
            handles.root.is_none_or(|r| r < nodes)
                && handles.joints.iter().all(|&n| n < nodes)
                && m.base
                    .as_ref()
                    .is_none_or(|b| b.joint_angles.nodes().all(|n| n < nodes))
        }
    };
    if ok {
        Ok(())
    } else {
        Err("the asset reads joints the character does not have: it was baked for another character".into())
    }
}

/// Compresses a fitted vertex-linear or vertex-clustered model into at
/// most `rank` eigen-AO basis rows ([`basis`]), found over the
/// per-pose `weights` ([`Model::weights`]) of the reference poses it
/// was fitted to. With a `threshold`, each vertex keeps only the basis
/// entries whose magnitude reaches it (and its mean), stored sparse.
/// `None` (and the model as it was) for the static average, or when
/// there is nothing to compress or the basis would not cost a vertex
/// fewer multiply-adds than the model does now.
pub fn compress(
    model: &mut Model,
    weights: &[Vec<f32>],
    rank: usize,
    threshold: f32,
) -> Option<BasisStats> {
    if matches!(model, Model::StaticAverage(_)) || weights.is_empty() {
        return None;
    }
    let cost = mean_multiply_adds(model, weights);
    let (basis, dense, mut stats) = basis::compress(model.form(), weights, rank)?;
    let form = if threshold > 0.0 {
        Coefficients::Sparse(SparseForm::from_dense(
            &dense.blocks[0],
            dense.vertices,
            threshold,
            &[basis.rank],
        ))
    } else {
        Coefficients::Dense(dense)
    };
    stats.threshold = threshold;
    stats.multiply_adds = match &form {
        Coefficients::Dense(f) => f.weight_count() as f64,
        Coefficients::Sparse(s) => s.multiply_adds(),
    };
    if stats.multiply_adds >= cost {
        return None;
    }
    match model {
        Model::StaticAverage(_) => unreachable!("returned above"),
        Model::VertexLinear(_, m) => {
            assert!(m.basis.is_none(), "compressed once");
            m.coefficients = form;
            m.basis = Some(basis);
        }
        Model::VertexClustered(_, m) => {
            assert!(m.basis.is_none(), "compressed once");
            m.form = form;
            m.basis = Some(basis);
        }
    }
    Some(stats)
}

/// What a fit reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case")]
pub enum FitStats {
    /// Nothing to report.
    StaticAverage,
    /// vertex-linear.
    VertexLinear(Box<LinearFitStats>),
    /// vertex-clustered.
    VertexClustered(Box<ClusteredFitStats>),
}

impl FitStats {
    /// How cross-validation over clips chose the reference rows, when it
    /// did (`reference = cv`).
    pub fn reference(&self) -> Option<&cv::RowsChoice> {
        match self {
            Self::VertexLinear(s) => s.reference.as_ref(),
            Self::VertexClustered(s) => s.reference.as_ref(),
            Self::StaticAverage => None,
        }
    }

    /// The eigen-AO compression, when there was one.
    pub fn basis(&self) -> Option<&BasisStats> {
        match self {
            Self::VertexLinear(s) => s.basis.as_ref(),
            Self::VertexClustered(s) => s.basis.as_ref(),
            Self::StaticAverage => None,
        }
    }

    /// How cross-validation over clips chose the basis rank, when it did.
    pub fn basis_cv(&self) -> Option<&BasisChoice> {
        match self {
            Self::VertexLinear(s) => s.basis_cv.as_ref(),
            Self::VertexClustered(s) => s.basis_cv.as_ref(),
            Self::StaticAverage => None,
        }
    }
}

/// The steps of a fit, reported in this order as each ends (what a fit
/// job's progress counts and `aobake bench bake` times). A step with
/// nothing to do ends at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitStep {
    /// Cross-validation over clips of the reference rows (`reference = cv`).
    ReferenceRows,
    /// The model: its ridge, locality (or per-vertex columns) and clamp by
    /// cross-validation over clips, and the fit to every row.
    Model,
    /// Cross-validation over clips of the eigen-AO basis.
    Basis,
    /// The compression into the chosen basis.
    Compress,
}

impl FitStep {
    /// Every step, in order.
    pub const ALL: [Self; 4] = [
        Self::ReferenceRows,
        Self::Model,
        Self::Basis,
        Self::Compress,
    ];

    /// Steps done once this one has ended.
    pub fn done(self) -> u64 {
        Self::ALL
            .iter()
            .position(|&s| s == self)
            .map_or(0, |i| i as u64 + 1)
    }

    /// Its name, as benches and progress lines print it.
    pub fn name(self) -> &'static str {
        match self {
            Self::ReferenceRows => "reference rows cv",
            Self::Model => "ridge cv and fit",
            Self::Basis => "basis cv",
            Self::Compress => "compress",
        }
    }
}

/// Fits `method` to the AO of the reference `poses` (the `fit` job's
/// work): the one place that turns a method name into a fitted model.
/// `seed` seeds k-means; `sources` says where each pose comes from, what
/// cross-validation over clips leaves out and scores. With random poses
/// and perturbed clip frames both there (`reference = cv`), a
/// vertex method is fitted to the rows [`cv::choose_rows`] chooses, each
/// candidate scored by vertex-linear over every parameter with the ridge
/// its cross-validation chooses;
/// the rows of random poses and clip frames when there are too few clips
/// to choose. The error says what to change. `on_step` is called on
/// this thread as each [`FitStep`] ends.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    method: Method,
    options: (&LinearOptions, &ClusteredOptions),
    seed: u64,
    character: &crate::Character,
    spaces: (&JointAngles, &Handles),
    poses: &[Pose],
    ao: &AoBlock,
    sources: &[Source],
    on_step: &mut dyn FnMut(FitStep),
) -> Result<(Model, FitStats), String> {
    let (joint_angles, _) = spaces;
    let pose_dependent = method.fits_poses();
    // The joint angles of every pose: what vertex-linear (and
    // vertex-clustered's linear base) reads, and what scores the rows.
    let q: Vec<Vec<f32>> = if pose_dependent {
        poses
            .iter()
            .map(|p| joint_angles.params(&character.skeleton, &p.locals))
            .collect()
    } else {
        vec![Vec::new(); poses.len()]
    };
    let (rows, choice) = if pose_dependent {
        let ranges = linear::Angles {
            ranges: &joint_angles.ranges,
            rotations: joint_angles.joints.len(),
        };
        cv::rows_to_fit(sources, |rows| {
            let q: Vec<Vec<f32>> = rows.iter().map(|&r| q[r].clone()).collect();
            let s: Vec<Source> = rows.iter().map(|&r| sources[r]).collect();
            // The candidate's rows read in place: three candidates side by
            // side would otherwise copy the block three times.
            let errors =
                linear::ridge_errors(&q, ranges, AoRows::some(ao, rows), &s, options.0, None)?;
            Some(errors.psnr[errors.best()?])
        })
    } else {
        (Rows::All, None)
    };
    on_step(FitStep::ReferenceRows);
    let (model, mut stats) = if rows == Rows::All {
        fit_rows(
            method,
            options,
            seed,
            character,
            spaces,
            poses,
            &q,
            AoRows::all(ao),
            sources,
            on_step,
        )?
    } else {
        let keep = rows.select(sources);
        let pick = |r: &usize| (poses[*r].clone(), q[*r].clone());
        let (poses, q): (Vec<Pose>, Vec<Vec<f32>>) = keep.iter().map(pick).unzip();
        let sources: Vec<Source> = keep.iter().map(|&r| sources[r]).collect();
        fit_rows(
            method,
            options,
            seed,
            character,
            spaces,
            &poses,
            &q,
            AoRows::some(ao, &keep),
            &sources,
            on_step,
        )?
    };
    match &mut stats {
        FitStats::VertexLinear(s) => s.reference = choice,
        FitStats::VertexClustered(s) => s.reference = choice,
        FitStats::StaticAverage => {}
    }
    Ok((model, stats))
}

/// [`fit`] to every row given; `q` holds the poses' joint angles (empty
/// for the static average).
#[allow(clippy::too_many_arguments)]
fn fit_rows(
    method: Method,
    options: (&LinearOptions, &ClusteredOptions),
    seed: u64,
    character: &crate::Character,
    spaces: (&JointAngles, &Handles),
    poses: &[Pose],
    q: &[Vec<f32>],
    ao: AoRows<'_>,
    sources: &[Source],
    on_step: &mut dyn FnMut(FitStep),
) -> Result<(Model, FitStats), String> {
    let (linear, _) = options;
    let (joint_angles, _) = spaces;
    let (mut model, mut stats) = match method {
        Method::StaticAverage => (
            Model::StaticAverage(average::fit(ao)),
            FitStats::StaticAverage,
        ),
        // texel-linear: vertex-linear over texels (`method::texel`).
        Method::VertexLinear | Method::TexelLinear => {
            let (m, stats) = fit_linear(character, joint_angles, q, ao, sources, linear)?;
            (
                Model::VertexLinear(joint_angles.clone(), m),
                FitStats::VertexLinear(Box::new(stats)),
            )
        }
        Method::VertexClustered => fit_clustered(
            character,
            spaces,
            options,
            seed,
            poses,
            q,
            &ao.to_block(),
            sources,
        )?,
        // Methods of other families have no per-vertex fit.
        other => return Err(format!("{other} is not a per-vertex method")),
    };
    on_step(FitStep::Model);
    add_basis(
        method,
        options,
        seed,
        character,
        spaces,
        (poses, q, ao, sources),
        (&mut model, &mut stats),
    );
    on_step(FitStep::Basis);
    on_step(FitStep::Compress);
    Ok((model, stats))
}

/// Kirk & Arikan's fit: pose clusters over the handles of the residual a
/// dense linear base leaves (or of the AO, with a mean base), with the
/// ridge weight and the clamp chosen by cross-validation over clips when
/// the options ask.
#[allow(clippy::too_many_arguments)]
fn fit_clustered(
    character: &crate::Character,
    spaces: (&JointAngles, &Handles),
    options: (&LinearOptions, &ClusteredOptions),
    seed: u64,
    poses: &[Pose],
    q: &[Vec<f32>],
    ao: &AoBlock,
    sources: &[Source],
) -> Result<(Model, FitStats), String> {
    let skeleton = &character.skeleton;
    let (linear, clustered) = options;
    let (joint_angles, handles) = spaces;
    let h: Vec<Vec<f32>> = poses
        .iter()
        .map(|p| handles.handles(skeleton, &p.locals))
        .collect();
    // A linear base is fitted first (global and dense, so that its
    // block can stand in the clustered form); the clusters then
    // model what it leaves.
    // The base's joint angles per pose (none without a base).
    let none = vec![Vec::new(); poses.len()];
    let q: &[Vec<f32>] = match clustered.base {
        clustered::Base::Mean => &none,
        clustered::Base::Linear => q,
    };
    let base = match clustered.base {
        clustered::Base::Mean => None,
        clustered::Base::Linear => {
            let dense = LinearOptions {
                locality: Locality::Off,
                per_vertex: false,
                threshold: 0.0,
                basis: 0,
                ..*linear
            };
            Some(fit_linear(
                character,
                joint_angles,
                q,
                AoRows::all(ao),
                sources,
                &dense,
            )?)
        }
    };
    let leftover;
    let ao = match &base {
        Some((m, _)) => {
            let mut values = Vec::with_capacity(ao.values.len());
            for (r, angles) in q.iter().enumerate() {
                let predicted = m.evaluate(angles);
                values.extend(ao.row(r).iter().zip(&predicted).map(|(a, b)| a - b));
            }
            leftover = AoBlock {
                vertices: ao.vertices,
                values,
            };
            &leftover
        }
        None => ao,
    };
    let (chosen, choice, clamp) = choose_clustered(&h, ao, sources, clustered, seed);
    let (m, mut stats) = clustered::fit(&h, ao, &chosen, seed).map_err(|e| e.to_string())?;
    stats.ridge_cv = choice;
    stats.clamp_cv = clamp;
    let m = match base {
        Some((linear_model, linear_stats)) => {
            stats.base = Some(linear_stats);
            clustered::with_base(m, joint_angles.clone(), linear_model)
        }
        None => m,
    };
    Ok((
        Model::VertexClustered(handles.clone(), m),
        FitStats::VertexClustered(Box::new(stats)),
    ))
}

/// vertex-clustered's ridge weight and then its clamp, each chosen by
/// cross-validation over clips when the options ask (else as given):
/// the options to fit with and the two choices.
fn choose_clustered(
    h: &[Vec<f32>],
    ao: &AoBlock,
    sources: &[Source],
    clustered: &ClusteredOptions,
    seed: u64,
) -> (
    ClusteredOptions,
    Option<cv::RidgeChoice>,
    Option<cv::RidgeChoice>,
) {
    let fit_on = |o: &ClusteredOptions, train: &[usize]| {
        let hs: Vec<Vec<f32>> = train.iter().map(|&r| h[r].clone()).collect();
        clustered::fit(&hs, &ao.select(train.iter().copied()), o, seed)
            .ok()
            .map(|(m, _)| m)
    };
    let predict = |m: &VertexClustered, r: usize| m.evaluate(&h[r]);
    let choice = clustered
        .ridge_cv
        .then(|| {
            let each_ridge = |train: &[usize]| {
                linear::RIDGE_CANDIDATES
                    .par_iter()
                    .map(|&ridge| {
                        fit_on(
                            &ClusteredOptions {
                                ridge,
                                ..*clustered
                            },
                            train,
                        )
                    })
                    .collect()
            };
            cv::choose_by_clips(sources, ao, &linear::RIDGE_CANDIDATES, each_ridge, predict)
        })
        .flatten();
    let mut chosen = ClusteredOptions {
        ridge: choice.as_ref().map_or(clustered.ridge, |c| c.ridge),
        ..*clustered
    };
    // The clamp only changes how a fitted model runs: one fit per
    // fold serves every candidate.
    let clamp = clustered
        .clamp_cv
        .then(|| {
            let each_clamp = |train: &[usize]| {
                let fitted = fit_on(&chosen, train);
                clustered::CLAMP_CANDIDATES
                    .iter()
                    .map(|&c| {
                        fitted.clone().map(|m| VertexClustered {
                            clamp: c as f32,
                            ..m
                        })
                    })
                    .collect()
            };
            cv::choose_by_clips(
                sources,
                ao,
                &clustered::CLAMP_CANDIDATES,
                each_clamp,
                predict,
            )
        })
        .flatten();
    if let Some(c) = &clamp {
        chosen.clamp = c.ridge as f32;
    }
    (chosen, choice, clamp)
}

/// Compresses a fitted model's per-vertex data onto a basis of at most
/// the options' rank (chosen, with its threshold, by cross-validation
/// over clips when they ask) and records it in `stats`.
fn add_basis(
    method: Method,
    options: (&LinearOptions, &ClusteredOptions),
    seed: u64,
    character: &crate::Character,
    spaces: (&JointAngles, &Handles),
    rows: (&[Pose], &[Vec<f32>], AoRows<'_>, &[Source]),
    fitted: (&mut Model, &mut FitStats),
) {
    let (linear, clustered) = options;
    let skeleton = &character.skeleton;
    let (poses, q, ao, sources) = rows;
    let (model, stats) = fitted;
    let (most, threshold, basis_cv) = match method {
        Method::VertexLinear | Method::TexelLinear => {
            (linear.basis, linear.basis_threshold, linear.basis_cv)
        }
        Method::VertexClustered => (
            clustered.basis,
            clustered.basis_threshold,
            clustered.basis_cv,
        ),
        // The static average has no basis; other families no vertices.
        _ => (0, 0.0, false),
    };
    if most > 0 {
        let weights: Vec<Vec<f32>> = poses
            .iter()
            .map(|p| model.weights(skeleton, &p.locals))
            .collect();
        let choice = if basis_cv {
            let settled = settled(options, stats);
            let fit = |train: &[usize]| {
                let pick = |r: &usize| (poses[*r].clone(), q[*r].clone());
                let (poses, q): (Vec<Pose>, Vec<Vec<f32>>) = train.iter().map(pick).unzip();
                let sources: Vec<Source> = train.iter().map(|&r| sources[r]).collect();
                // The fold's rows read in place, not copied (two folds side
                // by side held two copies of nearly the whole block).
                let rows = ao.rows_of(train);
                let fitted = fit_rows(
                    method,
                    (&settled.0, &settled.1),
                    seed,
                    character,
                    spaces,
                    &poses,
                    &q,
                    AoRows::some(ao.block(), &rows),
                    &sources,
                    &mut |_| {},
                );
                fitted.ok().map(|(m, _)| m)
            };
            let dense = method.family() == aobake_runtime::Family::Texel;
            basis_by_clips(
                skeleton,
                poses,
                ao,
                sources,
                (model, &weights),
                most,
                dense,
                fit,
            )
        } else {
            None
        };
        let (rank, threshold) = choice
            .as_ref()
            .map_or((most, threshold), |c| (c.rank, c.threshold));
        let basis = compress(model, &weights, rank, threshold);
        match stats {
            FitStats::VertexLinear(s) => (s.basis, s.basis_cv) = (basis, choice),
            FitStats::VertexClustered(s) => (s.basis, s.basis_cv) = (basis, choice),
            FitStats::StaticAverage => {}
        }
    }
}

/// `options` with what a fit chose (its `stats`) settled, and no basis:
/// the fit that cross-validation over clips repeats per fold to judge a
/// basis rank. A per-vertex vertex-linear still chooses its columns.
fn settled(
    options: (&LinearOptions, &ClusteredOptions),
    stats: &FitStats,
) -> (LinearOptions, ClusteredOptions) {
    let (linear, clustered) = options;
    // (vertex-clustered's linear base is never per vertex.)
    let base = LinearOptions {
        per_vertex: false,
        ..*linear
    };
    let settle = |o: &LinearOptions, s: &linear::LinearFitStats| LinearOptions {
        ridge: s.ridge,
        ridge_cv: o.per_vertex && o.ridge_cv,
        locality: match (o.per_vertex, s.local) {
            (true, _) => o.locality,
            (false, true) => Locality::On,
            (false, false) => Locality::Off,
        },
        basis: 0,
        basis_threshold: 0.0,
        basis_cv: false,
        ..*o
    };
    let clustered = ClusteredOptions {
        basis: 0,
        basis_threshold: 0.0,
        basis_cv: false,
        ..*clustered
    };
    match stats {
        FitStats::VertexLinear(s) => (settle(linear, s), clustered),
        FitStats::VertexClustered(s) => (
            s.base.as_ref().map_or(*linear, |b| settle(&base, b)),
            ClusteredOptions {
                ridge: s.ridge_cv.as_ref().map_or(clustered.ridge, |c| c.ridge),
                ridge_cv: false,
                clamp: s
                    .clamp_cv
                    .as_ref()
                    .map_or(clustered.clamp, |c| c.ridge as f32),
                clamp_cv: false,
                ..clustered
            },
        ),
        FitStats::StaticAverage => (*linear, clustered),
    }
}

/// What a model costs a vertex over the per-pose `weights`, on average.
fn mean_multiply_adds(model: &Model, weights: &[Vec<f32>]) -> f64 {
    weights.iter().map(|w| model.multiply_adds(w)).sum::<f64>() / weights.len().max(1) as f64
}

/// Chooses an eigen-AO basis (rows from 1 to `most`, a threshold of
/// [`cv::BASIS_THRESHOLDS`]) for `fitted` (the model fitted to every row,
/// and its weights per row) by cross-validation over clips
/// ([`cv::choose_basis`]): per group of clips, `fit(training rows)` fits
/// the model without a basis, and every candidate's truncation of its
/// predictions is scored on the left-out frames, clamped as the run time
/// clamps; each candidate costs what it would cost `fitted`, and one that
/// would not save `fitted` a multiply-add (so that it ships as fitted) is
/// scored as each fold's model as fitted. `None` when the frames come from
/// fewer than two clips. With `dense` (a texel method's) every candidate
/// keeps all its rows' entries.
#[allow(clippy::too_many_arguments)]
fn basis_by_clips(
    skeleton: &Skeleton,
    poses: &[Pose],
    ao: AoRows<'_>,
    sources: &[Source],
    fitted: (&Model, &[Vec<f32>]),
    most: usize,
    dense: bool,
    fit: impl Fn(&[usize]) -> Option<Model> + Sync,
) -> Option<BasisChoice> {
    use std::collections::HashMap;
    /// A fold's model: its basis axes, what each candidate would cost it,
    /// and its predictions of the left-out frames as coordinates along
    /// the axes, with the squared error of the model as fitted.
    struct Fold {
        truncations: basis::Truncations,
        predictions: HashMap<usize, (Vec<f64>, f64)>,
    }
    let (model, weights) = fitted;
    let whole = basis::Truncations::new(model.form(), weights, most)?;
    let cost = mean_multiply_adds(model, weights);
    // A texture holds every texel whatever its rows' small entries, so a
    // texel method's basis rows stay dense.
    let thresholds: &[f32] = if dense {
        &cv::BASIS_THRESHOLDS[..1]
    } else {
        &cv::BASIS_THRESHOLDS
    };
    let candidates: Vec<(usize, f32, f64)> = thresholds
        .iter()
        .flat_map(|&t| {
            let costs = whole.costs(t, most);
            (1..=most).map(move |r| (r, t, costs[r - 1].min(cost)))
        })
        .collect();
    // Per threshold, per rank: whether the basis saves the model that
    // ships a multiply-add (else it ships as fitted, and each fold is
    // scored so).
    let saves: Vec<Vec<bool>> = thresholds
        .iter()
        .map(|&t| whole.costs(t, most).iter().map(|&c| c < cost).collect())
        .collect();
    let fold = |train: &[usize]| -> Option<Fold> {
        let model = fit(train)?;
        let weights: Vec<Vec<f32>> = train
            .iter()
            .map(|&r| model.weights(skeleton, &poses[r].locals))
            .collect();
        let truncations = basis::Truncations::new(model.form(), &weights, most)?;
        let mut trained = vec![false; poses.len()];
        train.iter().for_each(|&r| trained[r] = true);
        let predictions = (0..poses.len())
            .into_par_iter()
            .filter(|&r| !trained[r] && matches!(sources[r], Source::Frame(_)))
            .map(|r| {
                let w = model.weights(skeleton, &poses[r].locals);
                let sse = model
                    .evaluate_weights(&w)
                    .iter()
                    .zip(ao.row(r))
                    .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
                    .sum();
                (r, (truncations.coordinates(&w), sse))
            })
            .collect();
        Some(Fold {
            truncations,
            predictions,
        })
    };
    let frame_sse = |fold: &Fold, r: usize| -> Vec<f64> {
        let (coordinates, fitted) = &fold.predictions[&r];
        thresholds
            .iter()
            .zip(&saves)
            .flat_map(|(&t, saves)| {
                let swept = fold.truncations.sweep(coordinates, t, ao.row(r), most);
                swept
                    .into_iter()
                    .zip(saves)
                    .map(|(e, &saves)| if saves { e } else { *fitted })
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let errors = cv::psnr_by_clips(sources, ao.columns(), candidates.len(), fold, frame_sse)?;
    cv::choose_basis(&candidates, &errors)
}

/// vertex-linear with every vertex's ridge, scope and pose dependence
/// chosen by cross-validation over clips ([`linear::choose_columns`]);
/// `None` when the rows come from fewer than two clips. The constant
/// vertices get the mean over the rows drawn from clips (every row when
/// none is): the static average a report compares with.
fn fit_linear_per_vertex(
    q: &[Vec<f32>],
    ranges: linear::Angles<'_>,
    ao: &AoBlock,
    sources: &[Source],
    options: &LinearOptions,
    sets: Option<&[Vec<usize>]>,
) -> Option<Result<(VertexLinear, linear::LinearFitStats), linear::FitOverflow>> {
    let baseline = |rows: &[usize]| {
        let frames: Vec<usize> = rows
            .iter()
            .copied()
            .filter(|&r| matches!(sources[r], Source::Frame(_)))
            .collect();
        let rows = if frames.is_empty() { rows } else { &frames };
        average::fit(AoRows::some(ao, rows)).evaluate()
    };
    let scopes: &[Scope] = match options.locality {
        Locality::Off => &[Scope::Global],
        Locality::On => &[Scope::Local],
        Locality::Cv => &[Scope::Global, Scope::Local],
    };
    let columns = linear::choose_columns(q, ranges, options, ao, sources, scopes, sets, baseline)?;
    let all: Vec<usize> = (0..sources.len()).collect();
    let constants = baseline(&all);
    Some(
        linear::fit_columns(
            q,
            ranges,
            AoRows::all(ao),
            &columns,
            sets,
            options,
            Some(&constants),
        )
        .map(|(m, mut stats)| {
            stats.per_vertex = Some(linear::count_columns(&columns));
            (m, stats)
        }),
    )
}

/// The part of `ranges` that the fitted rows' joint angles `q` cover, per
/// angle: what the model clamps a pose's angles to at run time. Random
/// poses cover the whole box of the clips' ranges; clip frames and
/// perturbed frames may not (a joint that no training clip moves far,
/// which only the perturbations move a little), and a linear model
/// carried past what it was fitted on extrapolates without bound. On the
/// unseen-clip folds it raised InterpolationTest's worst ones (a cube
/// scaled towards zero, which the perturbed rows reach only part way)
/// and changed no other shared character's.
fn covered(q: &[Vec<f32>], ranges: &[crate::pose_space::Range]) -> Vec<crate::pose_space::Range> {
    ranges
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let (lo, hi) = q
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p[k]), hi.max(p[k]))
                });
            if lo > hi {
                return *r;
            }
            crate::pose_space::Range {
                min: lo.clamp(r.min, r.max),
                max: hi.clamp(r.min, r.max),
            }
        })
        .collect()
}

/// vertex-linear over the joint angles `q` of every reference pose: the
/// locality, ridge (or per-vertex choice) by cross-validation over clips
/// as `linear` asks. vertex-clustered's linear base is one too.
fn fit_linear(
    character: &crate::Character,
    joint_angles: &JointAngles,
    q: &[Vec<f32>],
    ao: AoRows<'_>,
    sources: &[Source],
    linear: &LinearOptions,
) -> Result<(VertexLinear, linear::LinearFitStats), String> {
    let sets = (linear.locality != Locality::Off)
        .then(|| crate::pose_space::local_parameters(joint_angles, character));
    let covered = covered(q, &joint_angles.ranges);
    let ranges = linear::Angles {
        ranges: &covered,
        rotations: joint_angles.joints.len(),
    };
    if linear.per_vertex
        && let Some(fitted) =
            fit_linear_per_vertex(q, ranges, &ao.to_block(), sources, linear, sets.as_deref())
    {
        return fitted.map_err(|e| e.to_string());
    }
    let cv = |local: Option<&[Vec<usize>]>| {
        linear
            .ridge_cv
            .then(|| linear::choose_ridge(q, ranges, ao, sources, linear, local))
            .flatten()
    };
    let (local, choice) = match linear.locality {
        Locality::Off => (None, cv(None)),
        Locality::On => (sets.as_deref(), cv(sets.as_deref())),
        Locality::Cv => {
            let (global, near) = (cv(None), cv(sets.as_deref()));
            match (global, near) {
                (Some(g), Some(l)) if l.score() < g.score() => (sets.as_deref(), Some(l)),
                (g, _) => (None, g),
            }
        }
    };
    let chosen = LinearOptions {
        ridge: choice.as_ref().map_or(linear.ridge, |c| c.ridge),
        ..*linear
    };
    let (m, mut stats) = linear::fit(q, ranges, ao, &chosen, local).map_err(|e| e.to_string())?;
    stats.ridge_cv = choice;
    Ok((m, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose_space::Range;

    #[test]
    fn the_model_keeps_to_the_box_its_rows_cover() {
        let ranges = [
            Range {
                min: -1.0,
                max: 1.0,
            },
            Range { min: 0.0, max: 2.0 },
            Range { min: 0.0, max: 0.0 },
        ];
        // Rows cover [-0.5, 0.25] of the first, the second past its top
        // (the range wins), the third not at all.
        let q = vec![vec![-0.5, 1.0, 0.0], vec![0.25, 3.0, 0.0]];
        let c = covered(&q, &ranges);
        assert_eq!((c[0].min, c[0].max), (-0.5, 0.25));
        assert_eq!((c[1].min, c[1].max), (1.0, 2.0));
        assert_eq!((c[2].min, c[2].max), (0.0, 0.0));
        // No rows: the ranges as they are.
        assert_eq!(covered(&[], &ranges), ranges.to_vec());
    }
}
