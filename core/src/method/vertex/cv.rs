//! Cross-validation over clips: what the pose-dependent methods choose
//! their regularisation by, so that it is judged on motion the fit did
//! not see (frames of clips left out), not on poses between training
//! poses.

use serde::{Deserialize, Serialize};

use crate::trace::AoBlock;

/// Most groups of clips the cross-validation leaves out in turn.
pub const CV_FOLDS: usize = 8;

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
    /// The chosen value's RMSE over the left-out clips.
    pub fn score(&self) -> f64 {
        self.scores
            .iter()
            .find(|(c, _)| *c == self.ridge)
            .map_or(f64::INFINITY, |s| s.1)
    }
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
}

/// Leaves groups of clips out: `groups` is each row of `ao`'s clip
/// (`None`: a random pose, always trained on); the clips are dealt into up
/// to [`CV_FOLDS`] groups, and for each group `fit(training rows)` gives
/// one model per candidate (`None`: that candidate cannot be fitted, its
/// errors are infinite), each scored by `predict(model, row)` on the
/// group's rows. A candidate that changes only how a model runs can share
/// one fit. `None` when the rows come from fewer than two clips.
pub fn sse_by_clips<M>(
    groups: &[Option<usize>],
    ao: &AoBlock,
    candidates: usize,
    fit: impl Fn(&[usize]) -> Vec<Option<M>>,
    predict: impl Fn(&M, usize) -> Vec<f32>,
) -> Option<ClipErrors> {
    let mut clips: Vec<usize> = groups.iter().flatten().copied().collect();
    clips.sort_unstable();
    clips.dedup();
    if clips.len() < 2 || candidates == 0 {
        return None;
    }
    let folds = clips.len().min(CV_FOLDS);
    let fold_of = |c: usize| clips.binary_search(&c).map_or(0, |i| i % folds);
    let mut sse = vec![vec![0.0f64; ao.vertices]; candidates];
    let mut rows = 0usize;
    for f in 0..folds {
        let held = |g: &Option<usize>| g.is_some_and(|c| fold_of(c) == f);
        let train: Vec<usize> = (0..groups.len()).filter(|&r| !held(&groups[r])).collect();
        let test: Vec<usize> = (0..groups.len()).filter(|&r| held(&groups[r])).collect();
        if train.is_empty() || test.is_empty() {
            continue;
        }
        rows += test.len();
        let models = fit(&train);
        for (k, e) in sse.iter_mut().enumerate() {
            let Some(model) = models.get(k).and_then(Option::as_ref) else {
                e.iter_mut().for_each(|x| *x = f64::INFINITY);
                continue;
            };
            for &r in &test {
                for ((x, &a), &b) in e.iter_mut().zip(&predict(model, r)).zip(ao.row(r)) {
                    *x += (f64::from(a) - f64::from(b)).powi(2);
                }
            }
        }
    }
    Some(ClipErrors { sse, rows, folds })
}

/// Chooses among `candidates` by leaving groups of clips out (see
/// [`sse_by_clips`]): the candidate with the least squared error over
/// all left-out rows and vertices wins (the first on a tie). `None` when
/// the rows come from fewer than two clips.
pub fn choose_by_clips<M>(
    groups: &[Option<usize>],
    ao: &AoBlock,
    candidates: &[f64],
    fit: impl Fn(&[usize]) -> Vec<Option<M>>,
    predict: impl Fn(&M, usize) -> Vec<f32>,
) -> Option<RidgeChoice> {
    let errors = sse_by_clips(groups, ao, candidates.len(), fit, predict)?;
    let n = (errors.rows * ao.vertices).max(1) as f64;
    let scores: Vec<(f64, f64)> = candidates
        .iter()
        .zip(&errors.sse)
        .map(|(&c, e)| (c, (e.iter().sum::<f64>() / n).sqrt()))
        .collect();
    let best = scores.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1))?.0;
    Some(RidgeChoice {
        ridge: best,
        scores,
        folds: errors.folds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_candidate_that_predicts_left_out_clips_best_wins() {
        // Two clips; the "model" predicts the candidate itself everywhere.
        // Clip 0's rows are 0.2, clip 1's 0.4; random rows are ignored.
        let ao = AoBlock {
            vertices: 1,
            values: vec![0.9, 0.2, 0.2, 0.4, 0.4],
        };
        let groups = [None, Some(0), Some(0), Some(1), Some(1)];
        let candidates = [0.0, 0.3, 1.0];
        let each = |_: &[usize]| candidates.iter().map(|&v| Some(v)).collect();
        let c = choose_by_clips(&groups, &ao, &candidates, each, |&v, _| vec![v as f32]).unwrap();
        assert_eq!((c.ridge, c.folds), (0.3, 2));
        assert!((c.scores[1].1 - 0.1).abs() < 1e-6);
        // One clip: nothing to leave out.
        let one = [None, Some(0), Some(0), Some(0), Some(0)];
        assert!(choose_by_clips(&one, &ao, &candidates, each, |&v, _| vec![v as f32]).is_none());
    }
}
