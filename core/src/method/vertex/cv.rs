//! Cross-validation over clips: what the pose-dependent methods choose
//! their regularisation by, so that it is judged on motion the fit did
//! not see (frames of clips left out), not on poses between training
//! poses.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::trace::AoBlock;

/// Most groups of clips the cross-validation leaves out in turn.
pub const CV_FOLDS: usize = 8;

/// Where a reference row comes from: what cross-validation over clips
/// leaves out with a clip, and what it scores.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Source {
    /// A random pose: always trained on, never scored.
    Random,
    /// A frame of this clip: left out with the clip and scored (motion).
    Frame(usize),
    /// A perturbed frame of this clip: left out with the clip, not scored
    /// (it is no motion anybody animated).
    Perturbed(usize),
}

impl Source {
    /// The clip the row comes from (`None`: a random pose).
    pub fn clip(self) -> Option<usize> {
        match self {
            Self::Random => None,
            Self::Frame(c) | Self::Perturbed(c) => Some(c),
        }
    }
}

/// What a cross-validation over clips found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RidgeChoice {
    /// The chosen value.
    pub ridge: f64,
    /// Per candidate: (value, RMSE over the left-out clips' frames).
    pub scores: Vec<(f64, f64)>,
    /// Groups of clips left out in turn.
    pub folds: usize,
}

impl RidgeChoice {
    /// The candidate of `candidates` with the least RMSE in `errors` (the
    /// first on a tie).
    pub fn of(candidates: &[f64], errors: &ClipErrors) -> Option<Self> {
        let scores: Vec<(f64, f64)> = candidates
            .iter()
            .enumerate()
            .map(|(k, &c)| (c, errors.rmse(k)))
            .collect();
        Some(Self {
            ridge: candidates[errors.best()?],
            scores,
            folds: errors.folds,
        })
    }

    /// The chosen value's RMSE over the left-out clips.
    pub fn score(&self) -> f64 {
        self.scores
            .iter()
            .find(|(c, _)| *c == self.ridge)
            .map_or(f64::INFINITY, |s| s.1)
    }
}

/// Decibels a cheaper eigen-AO basis may lose on left-out clips against
/// the best and still be chosen ([`choose_basis`]): a tenth of a decibel
/// is 2.3 % of the error, less than the spread between bakes with other
/// seeds, so what costs more past it buys run-time cost, not quality.
pub const BASIS_TOLERANCE_DB: f64 = 0.1;

/// The thresholds below which a basis's entries are dropped that
/// [`choose_basis`] chooses among (AO per standard deviation of a basis
/// weight; 0 keeps the rows dense).
pub const BASIS_THRESHOLDS: [f32; 5] = [0.0, 1.0 / 2048.0, 1.0 / 1024.0, 1.0 / 512.0, 1.0 / 256.0];

/// One eigen-AO basis cross-validation over clips judged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BasisCandidate {
    /// Basis rows.
    pub rank: usize,
    /// Entries below this dropped.
    pub threshold: f32,
    /// Mean PSNR over the left-out clips' frames (dB, see
    /// [`ClipErrors::psnr`]).
    pub psnr_db: f64,
    /// What it costs the model fitted to every row, per vertex.
    pub multiply_adds: f64,
}

/// How cross-validation over clips chose an eigen-AO basis: its rows and
/// threshold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BasisChoice {
    /// The chosen rows.
    pub rank: usize,
    /// The chosen threshold.
    pub threshold: f32,
    /// Every candidate.
    pub candidates: Vec<BasisCandidate>,
    /// How far below the best score the chosen one may be (dB).
    pub tolerance_db: f64,
    /// Groups of clips left out in turn.
    pub folds: usize,
}

impl BasisChoice {
    /// The chosen candidate.
    pub fn chosen(&self) -> Option<&BasisCandidate> {
        self.candidates
            .iter()
            .find(|c| c.rank == self.rank && c.threshold == self.threshold)
    }

    /// The best-scoring candidate.
    pub fn best(&self) -> Option<&BasisCandidate> {
        self.candidates
            .iter()
            .max_by(|a, b| a.psnr_db.total_cmp(&b.psnr_db))
    }
}

/// Chooses among basis `candidates` (rank, threshold, multiply-adds),
/// scored in that order in `errors`: the cheapest whose mean PSNR over the
/// left-out clips is within [`BASIS_TOLERANCE_DB`] of the best (on a tie,
/// the better scored, then the fewer rows). `None` without a finite
/// score.
pub fn choose_basis(candidates: &[(usize, f32, f64)], errors: &ClipErrors) -> Option<BasisChoice> {
    let candidates: Vec<BasisCandidate> = candidates
        .iter()
        .zip(&errors.psnr)
        .map(
            |(&(rank, threshold, multiply_adds), &psnr_db)| BasisCandidate {
                rank,
                threshold,
                psnr_db,
                multiply_adds,
            },
        )
        .collect();
    let best = candidates
        .iter()
        .map(|c| c.psnr_db)
        .filter(|x| x.is_finite())
        .max_by(f64::total_cmp)?;
    let chosen = candidates
        .iter()
        .filter(|c| c.psnr_db >= best - BASIS_TOLERANCE_DB)
        .min_by(|a, b| {
            a.multiply_adds
                .total_cmp(&b.multiply_adds)
                .then(b.psnr_db.total_cmp(&a.psnr_db))
                .then(a.rank.cmp(&b.rank))
        })?;
    Some(BasisChoice {
        rank: chosen.rank,
        threshold: chosen.threshold,
        tolerance_db: BASIS_TOLERANCE_DB,
        folds: errors.folds,
        candidates,
    })
}

/// Which reference rows a fit uses when it has random poses, clip frames
/// and perturbed clip frames (`reference = cv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rows {
    /// Random poses and clip frames (`reference = mixed`).
    Mixed,
    /// Clip frames and perturbed clip frames (`reference = perturbed`).
    Perturbed,
    /// All three.
    All,
}

impl Rows {
    /// The candidates, in the order a tie goes.
    pub const CANDIDATES: [Self; 3] = [Self::Mixed, Self::Perturbed, Self::All];

    /// Whether a row from `source` is in the set.
    pub fn keeps(self, source: Source) -> bool {
        match (self, source) {
            (Self::All, _) | (_, Source::Frame(_)) => true,
            (Self::Mixed, s) => s == Source::Random,
            (Self::Perturbed, s) => s != Source::Random,
        }
    }

    /// The indices of `sources` in the set.
    pub fn select(self, sources: &[Source]) -> Vec<usize> {
        (0..sources.len())
            .filter(|&r| self.keeps(sources[r]))
            .collect()
    }
}

/// How cross-validation over clips chose the reference rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RowsChoice {
    /// The rows the model was fitted to.
    pub rows: Rows,
    /// Per candidate: its mean PSNR over the left-out clips' frames (dB,
    /// see [`ClipErrors::psnr`]).
    pub scores: Vec<(Rows, f64)>,
}

/// The rows a fit to `sources` uses: every row unless there are random
/// poses and perturbed frames both; then the ones [`choose_rows`] chooses,
/// or [`Rows::Mixed`]'s when it cannot choose (frames of fewer than two
/// clips). The choice comes along when there was one.
pub fn rows_to_fit(
    sources: &[Source],
    score: impl Fn(&[usize]) -> Option<f64> + Sync,
) -> (Rows, Option<RowsChoice>) {
    if !offers_choice(sources) {
        return (Rows::All, None);
    }
    match choose_rows(sources, score) {
        Some(c) => (c.rows, Some(c)),
        None => (Rows::Mixed, None),
    }
}

/// Whether `sources` has random poses and perturbed frames to choose
/// between.
fn offers_choice(sources: &[Source]) -> bool {
    sources.contains(&Source::Random) && sources.iter().any(|s| matches!(s, Source::Perturbed(_)))
}

/// Chooses the reference rows by cross-validation over clips: `score(rows)`
/// is a candidate's mean PSNR over the left-out clips' frames (the frames,
/// and so the scored rows and folds, are in every candidate), and the
/// highest wins, [`Rows::Mixed`] on a tie. `None` unless there are random poses
/// and perturbed frames to choose between, or when a score is `None`
/// (frames of fewer than two clips).
pub fn choose_rows(
    sources: &[Source],
    score: impl Fn(&[usize]) -> Option<f64> + Sync,
) -> Option<RowsChoice> {
    if !offers_choice(sources) {
        return None;
    }
    // The candidates are scored side by side, each on its own thread.
    let scores: Vec<(Rows, f64)> = Rows::CANDIDATES
        .par_iter()
        .map(|&rows| Some((rows, score(&rows.select(sources))?)))
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Option<_>>()?;
    let rows = scores.iter().rev().max_by(|a, b| a.1.total_cmp(&b.1))?.0;
    Some(RowsChoice { rows, scores })
}

/// Squared errors over left-out clips, per candidate and vertex, from
/// [`sse_by_clips`].
#[derive(Debug, Clone, PartialEq)]
pub struct ClipErrors {
    /// `sse[candidate][vertex]`: summed over every left-out row.
    pub sse: Vec<Vec<f64>>,
    /// Left-out rows summed over.
    pub rows: usize,
    /// Groups of clips left out in turn.
    pub folds: usize,
    /// `psnr[candidate]`: over the groups, the mean of each group's mean
    /// per-frame PSNR (dB), the figure the report's unseen clips give.
    pub psnr: Vec<f64>,
}

impl ClipErrors {
    /// A candidate's RMSE over every left-out row and vertex.
    pub fn rmse(&self, candidate: usize) -> f64 {
        let n = (self.rows * self.sse[candidate].len()).max(1) as f64;
        (self.sse[candidate].iter().sum::<f64>() / n).sqrt()
    }

    /// The candidate with the least RMSE (the first on a tie); `None`
    /// without candidates.
    pub fn best(&self) -> Option<usize> {
        (0..self.sse.len()).min_by(|&a, &b| self.rmse(a).total_cmp(&self.rmse(b)))
    }
}

/// Leaves groups of clips out: `sources` says where each row of `ao`
/// comes from (see [`Source`]); the clips are dealt into up to
/// [`CV_FOLDS`] groups, and for each group `fit(training rows)` gives one
/// model per candidate (`None`: that candidate cannot be fitted, its
/// errors are infinite), each scored by `predict(model, row)` on the
/// group's frames. A candidate that changes only how a model runs can
/// share one fit. `None` when the frames come from fewer than two clips.
pub fn sse_by_clips<M: Send + Sync>(
    sources: &[Source],
    ao: &AoBlock,
    candidates: usize,
    fit: impl Fn(&[usize]) -> Vec<Option<M>> + Sync,
    predict: impl Fn(&M, usize) -> Vec<f32> + Sync,
) -> Option<ClipErrors> {
    let columns = Columns {
        count: ao.vertices,
        chunk: ao.vertices.max(1),
    };
    sse_by_clips_in_columns(
        sources,
        |r| ao.row(r),
        columns,
        candidates,
        |train, _| fit(train),
        |model, r, _| predict(model, r),
    )
}

/// How many columns (vertices, texels) a block has, and how many of them
/// [`sse_by_clips_in_columns`] fits and scores at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Columns {
    /// Columns in all.
    pub count: usize,
    /// Columns fitted and scored at a time (at least 1).
    pub chunk: usize,
}

impl Columns {
    /// The chunks, in order.
    fn chunks(self) -> impl Iterator<Item = std::ops::Range<usize>> {
        let chunk = self.chunk.max(1);
        (0..self.count)
            .step_by(chunk)
            .map(move |start| start..(start + chunk).min(self.count))
    }
}

/// [`sse_by_clips`] a chunk of columns at a time, so that no group's
/// candidate models over every column are held at once: for each group
/// and each chunk `cols` of `columns`, `fit(training rows, cols)` gives
/// one model per candidate over those columns, scored by `predict(model,
/// row, cols)` (the chunk's predictions) against `truth(row)[cols]`. A
/// row is an index into `sources`; `truth(row)` is all its columns. Each
/// column's errors and each frame's running sum over the columns are
/// added in the same order as in one chunk, so the result is the same
/// bits whatever the chunk (and on any number of threads).
pub fn sse_by_clips_in_columns<'a, M: Send + Sync>(
    sources: &[Source],
    truth: impl Fn(usize) -> &'a [f32] + Sync,
    columns: Columns,
    candidates: usize,
    fit: impl Fn(&[usize], std::ops::Range<usize>) -> Vec<Option<M>> + Sync,
    predict: impl Fn(&M, usize, std::ops::Range<usize>) -> Vec<f32> + Sync,
) -> Option<ClipErrors> {
    let (folds, groups) = clip_folds(sources)?;
    if candidates == 0 {
        return None;
    }
    let v = columns.count;
    // Each group is fitted and scored on its own thread, its sums started
    // from zero; the groups are then added in their order, so the result
    // is the same bits on any number of threads.
    let per_group: Vec<(Vec<Vec<f64>>, Vec<f64>)> = groups
        .par_iter()
        .map(|(train, test)| {
            // Per candidate: its errors per column, each test frame's
            // running sum over the columns, and whether it could be
            // fitted on every chunk.
            let mut sums: Vec<(Vec<f64>, Vec<f64>, bool)> = (0..candidates)
                .map(|_| (vec![0.0f64; v], vec![0.0f64; test.len()], true))
                .collect();
            for cols in columns.chunks() {
                let models = fit(train, cols.clone());
                // Each candidate scored on its own thread, its rows in order.
                sums.par_iter_mut()
                    .enumerate()
                    .for_each(|(k, (e, frames, fitted))| {
                        let Some(model) = models.get(k).and_then(Option::as_ref) else {
                            *fitted = false;
                            return;
                        };
                        if !*fitted {
                            return;
                        }
                        let e = &mut e[cols.clone()];
                        for (frame, &r) in frames.iter_mut().zip(test) {
                            let predicted = predict(model, r, cols.clone());
                            for ((x, &a), &b) in
                                e.iter_mut().zip(&predicted).zip(&truth(r)[cols.clone()])
                            {
                                let d = (f64::from(a) - f64::from(b)).powi(2);
                                *x += d;
                                *frame += d;
                            }
                        }
                    });
            }
            sums.into_iter()
                .map(|(e, frames, fitted)| {
                    if !fitted {
                        return (vec![f64::INFINITY; v], f64::NEG_INFINITY);
                    }
                    let psnr = frames
                        .iter()
                        .map(|&f| crate::asset::metrics::psnr(f / v.max(1) as f64))
                        .sum::<f64>();
                    (e, psnr / test.len() as f64)
                })
                .unzip::<_, _, Vec<_>, Vec<_>>()
        })
        .collect();
    let mut sse = vec![vec![0.0f64; v]; candidates];
    let mut fold_psnr = vec![Vec::new(); candidates];
    for (group_sse, group_psnr) in per_group {
        for (total, e) in sse.iter_mut().zip(group_sse) {
            total.iter_mut().zip(e).for_each(|(t, x)| *t += x);
        }
        for (p, x) in fold_psnr.iter_mut().zip(group_psnr) {
            p.push(x);
        }
    }
    Some(ClipErrors {
        sse,
        rows: groups.iter().map(|(_, test)| test.len()).sum(),
        folds,
        psnr: mean_over_folds(&fold_psnr),
    })
}

/// Per candidate, the mean of its per-group figures.
fn mean_over_folds(fold_psnr: &[Vec<f64>]) -> Vec<f64> {
    fold_psnr
        .iter()
        .map(|f| f.iter().sum::<f64>() / f.len().max(1) as f64)
        .collect()
}

/// The groups of clips cross-validation over clips leaves out in turn:
/// how many groups the clips are dealt into (at most [`CV_FOLDS`]), and
/// per group with rows on both sides its training rows (every row not
/// from its clips) and its test rows (its clips' plain frames). `None`
/// when the frames come from fewer than two clips.
#[allow(clippy::type_complexity)]
fn clip_folds(sources: &[Source]) -> Option<(usize, Vec<(Vec<usize>, Vec<usize>)>)> {
    let mut clips: Vec<usize> = sources
        .iter()
        .filter_map(|s| match s {
            Source::Frame(c) => Some(*c),
            _ => None,
        })
        .collect();
    clips.sort_unstable();
    clips.dedup();
    if clips.len() < 2 {
        return None;
    }
    let folds = clips.len().min(CV_FOLDS);
    let fold_of = |c: usize| clips.binary_search(&c).ok().map(|i| i % folds);
    let groups = (0..folds)
        .map(|f| {
            let held = |s: Source| s.clip().and_then(fold_of) == Some(f);
            let train: Vec<usize> = (0..sources.len()).filter(|&r| !held(sources[r])).collect();
            let test: Vec<usize> = (0..sources.len())
                .filter(|&r| matches!(sources[r], Source::Frame(_)) && held(sources[r]))
                .collect();
            (train, test)
        })
        .filter(|(train, test)| !train.is_empty() && !test.is_empty())
        .collect();
    Some((folds, groups))
}

/// Like [`sse_by_clips`], for candidates that one fit per group serves
/// and one pass over a frame scores together: `fit(training rows)` gives
/// the group's model (`None`: every candidate's errors are infinite), and
/// `frame_sse(model, row)` each candidate's squared error summed over the
/// vertices of that frame. Only the PSNRs are kept (`sse` is empty).
pub fn psnr_by_clips<M: Sync>(
    sources: &[Source],
    columns: usize,
    candidates: usize,
    fit: impl Fn(&[usize]) -> Option<M> + Sync,
    frame_sse: impl Fn(&M, usize) -> Vec<f64> + Sync,
) -> Option<ClipErrors> {
    let (folds, groups) = clip_folds(sources)?;
    if candidates == 0 {
        return None;
    }
    // One group per thread, each group's figures its own (see
    // `sse_by_clips`).
    let per_group: Vec<Vec<f64>> = groups
        .par_iter()
        .map(|(train, test)| {
            let Some(model) = fit(train) else {
                return vec![f64::NEG_INFINITY; candidates];
            };
            // The frames scored side by side, added in their order.
            let scored: Vec<Vec<f64>> = test.par_iter().map(|&r| frame_sse(&model, r)).collect();
            let mut frames = vec![0.0f64; candidates];
            for sse in scored {
                assert_eq!(sse.len(), candidates, "one error per candidate");
                for (f, e) in frames.iter_mut().zip(sse) {
                    *f += crate::asset::metrics::psnr(e / columns.max(1) as f64);
                }
            }
            frames.iter().map(|f| f / test.len() as f64).collect()
        })
        .collect();
    let mut fold_psnr = vec![Vec::new(); candidates];
    for group in per_group {
        for (p, x) in fold_psnr.iter_mut().zip(group) {
            p.push(x);
        }
    }
    Some(ClipErrors {
        sse: Vec::new(),
        rows: groups.iter().map(|(_, test)| test.len()).sum(),
        folds,
        psnr: mean_over_folds(&fold_psnr),
    })
}

/// Chooses among `candidates` by leaving groups of clips out (see
/// [`sse_by_clips`]): the candidate with the least squared error over
/// all left-out frames and vertices wins (the first on a tie). `None` when
/// the frames come from fewer than two clips.
pub fn choose_by_clips<M: Send + Sync>(
    sources: &[Source],
    ao: &AoBlock,
    candidates: &[f64],
    fit: impl Fn(&[usize]) -> Vec<Option<M>> + Sync,
    predict: impl Fn(&M, usize) -> Vec<f32> + Sync,
) -> Option<RidgeChoice> {
    RidgeChoice::of(
        candidates,
        &sse_by_clips(sources, ao, candidates.len(), fit, predict)?,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_candidate_that_predicts_left_out_clips_best_wins() {
        // Two clips; the "model" predicts the candidate itself everywhere.
        // Clip 0's frames are 0.2, clip 1's 0.4; random and perturbed rows
        // are not scored.
        let ao = AoBlock {
            vertices: 1,
            values: vec![0.9, 0.2, 0.2, 0.4, 0.4, 0.9],
        };
        use Source::{Frame, Perturbed, Random};
        let sources = [Random, Frame(0), Frame(0), Frame(1), Frame(1), Perturbed(1)];
        let candidates = [0.0, 0.3, 1.0];
        let trained = std::sync::Mutex::new(Vec::new());
        let each = |train: &[usize]| {
            trained.lock().unwrap().push(train.to_vec());
            candidates.iter().map(|&v| Some(v)).collect()
        };
        let c = choose_by_clips(&sources, &ao, &candidates, each, |&v, _| vec![v as f32]).unwrap();
        assert_eq!((c.ridge, c.folds), (0.3, 2));
        assert!((c.scores[1].1 - 0.1).abs() < 1e-6);
        // A perturbed frame leaves with its clip; a random pose never does.
        let mut trained = trained.lock().unwrap().clone();
        trained.sort();
        assert_eq!(trained, [vec![0, 1, 2], vec![0, 3, 4, 5]]);
        // Frames of one clip: nothing to leave out.
        let one = [Random, Frame(0), Frame(0), Frame(0), Frame(0), Perturbed(1)];
        assert!(choose_by_clips(&one, &ao, &candidates, each, |&v, _| vec![v as f32]).is_none());
    }

    #[test]
    fn scoring_a_chunk_of_columns_at_a_time_gives_the_same_bits() {
        use Source::{Frame, Random};
        // Three clips' frames and random rows over seven columns; each
        // candidate predicts its factor times the training rows' mean.
        let (v, p) = (7, 12);
        let ao = AoBlock {
            vertices: v,
            values: (0..v * p)
                .map(|i| ((i as f32) * 0.618).fract() * 0.9)
                .collect(),
        };
        let sources: Vec<Source> = (0..p)
            .map(|r| if r % 4 == 3 { Random } else { Frame(r % 3) })
            .collect();
        let factors = [0.5f32, 1.0, 1.5];
        let score = |chunk: usize| {
            sse_by_clips_in_columns(
                &sources,
                |r| ao.row(r),
                Columns { count: v, chunk },
                factors.len(),
                |train, cols| {
                    let mean: Vec<f32> = cols
                        .clone()
                        .map(|c| {
                            train.iter().map(|&r| ao.row(r)[c]).sum::<f32>() / train.len() as f32
                        })
                        .collect();
                    factors
                        .iter()
                        .map(|&f| Some(mean.iter().map(|m| m * f).collect::<Vec<f32>>()))
                        .collect()
                },
                |model, _, cols| {
                    assert_eq!(model.len(), cols.len(), "one prediction per column");
                    model.clone()
                },
            )
            .unwrap()
        };
        let whole = score(v);
        assert_eq!((whole.folds, whole.sse.len()), (3, 3));
        assert_eq!(whole.best(), Some(1), "the mean itself predicts best");
        for chunk in [1, 2, 3, 100] {
            assert_eq!(score(chunk), whole, "chunks of {chunk}");
        }
    }

    #[test]
    fn the_cheapest_basis_within_the_tolerance_of_the_best_wins() {
        let errors = |psnr: Vec<f64>| ClipErrors {
            sse: vec![Vec::new(); psnr.len()],
            rows: 1,
            folds: 2,
            psnr,
        };
        // (rank, threshold, multiply-adds)
        let candidates = [
            (1, 0.0, 2.0),
            (2, 0.0, 3.0),
            (3, 0.0, 4.0),
            (3, 0.01, 2.5),
            (4, 0.0, 5.0),
        ];
        // The best is rank 4 (30 dB); rank 3 with its small entries
        // dropped is within a tenth of a decibel and cheaper than rank 3
        // dense; rank 2 is just outside.
        let c = choose_basis(&candidates, &errors(vec![20.0, 29.89, 29.95, 29.91, 30.0])).unwrap();
        assert_eq!((c.rank, c.threshold, c.folds), (3, 0.01, 2));
        assert_eq!(c.chosen().unwrap().psnr_db, 29.91);
        assert_eq!(c.best().unwrap().rank, 4);
        assert_eq!(c.tolerance_db, BASIS_TOLERANCE_DB);
        // A tie on cost goes to the better scored.
        let tie = [(1, 0.0, 2.0), (2, 0.01, 2.0)];
        assert_eq!(
            choose_basis(&tie, &errors(vec![1.0, 1.05])).unwrap().rank,
            2
        );
        // A candidate that could not be fitted never wins; with none that
        // could, there is no choice.
        let c = choose_basis(
            &candidates,
            &errors(vec![f64::NEG_INFINITY, 1.0, 2.0, 1.0, 2.0]),
        )
        .unwrap();
        assert_eq!(c.rank, 3);
        assert!(choose_basis(&candidates, &errors(vec![f64::NEG_INFINITY; 5])).is_none());
    }

    #[test]
    fn the_reference_rows_that_score_best_win() {
        use Source::{Frame, Perturbed, Random};
        let sources = [Random, Frame(0), Perturbed(0), Frame(1), Perturbed(1)];
        assert_eq!(Rows::Mixed.select(&sources), [0, 1, 3]);
        assert_eq!(Rows::Perturbed.select(&sources), [1, 2, 3, 4]);
        assert_eq!(Rows::All.select(&sources), [0, 1, 2, 3, 4]);
        // The score here: fewer rows, more dB.
        let c = choose_rows(&sources, |rows| Some(-(rows.len() as f64))).unwrap();
        assert_eq!(c.rows, Rows::Mixed);
        assert_eq!(c.scores[2], (Rows::All, -5.0));
        let c = choose_rows(&sources, |rows| Some(rows.len() as f64)).unwrap();
        assert_eq!(c.rows, Rows::All);
        // A tie goes to the first.
        assert_eq!(
            choose_rows(&sources, |_| Some(1.0)).unwrap().rows,
            Rows::Mixed
        );
        // Nothing to choose without random poses or perturbed frames, and
        // no choice without a score.
        assert!(choose_rows(&sources[1..], |_| Some(0.0)).is_none());
        assert!(choose_rows(&[Random, Frame(0), Frame(1)], |_| Some(0.0)).is_none());
        assert!(choose_rows(&sources, |_| None).is_none());
        // What a fit uses: every row without a choice to make, mixed's
        // rows when it cannot choose.
        assert_eq!(rows_to_fit(&sources[1..], |_| Some(0.0)), (Rows::All, None));
        assert_eq!(rows_to_fit(&sources, |_| None), (Rows::Mixed, None));
        let (rows, choice) = rows_to_fit(&sources, |rows| Some(rows.len() as f64));
        assert_eq!((rows, choice.map(|c| c.rows)), (Rows::All, Some(Rows::All)));
    }
}
