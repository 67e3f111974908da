//! How long a bake has left, from its jobs: each stage (job kind) at its
//! own pace. Tracing, fitting, judging and previews take very different
//! times per unit of work, so one rate over all units (what a progress bar
//! knows) says "0 s" while the last, slow jobs run. Here each kind's
//! seconds per unit come from its own finished jobs (lease to completion,
//! `started_at` to `finished_at`), and the work left is spread over the
//! jobs running side by side. The dashboard computes the same in
//! JavaScript (`timeLeft` in `server/src/dashboard/assets/app.js`).

use std::collections::BTreeMap;

use crate::types::{JobRow, JobState};

/// An estimate of the time a bake has left.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeLeft {
    /// Nothing left to run.
    Done,
    /// About this many seconds.
    Seconds(f64),
    /// No job of these kinds has finished yet, so their pace is unknown
    /// (the seconds of the kinds that are known, as a floor).
    Unknown {
        /// Kinds with work left and no finished job.
        kinds: Vec<String>,
        /// Seconds the known kinds have left.
        at_least: f64,
    },
}

impl std::fmt::Display for TimeLeft {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Done => write!(f, "nothing left"),
            Self::Seconds(s) => write!(f, "about {} left", human(*s)),
            Self::Unknown { kinds, at_least } => write!(
                f,
                "at least {} left (no {} job has finished yet)",
                human(*at_least),
                kinds.join(" or ")
            ),
        }
    }
}

/// Seconds as people say them.
fn human(s: f64) -> String {
    if s < 60.0 {
        format!("{} s", s.round().max(1.0))
    } else if s < 3600.0 {
        format!("{} min", (s / 60.0).round())
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

/// The time `jobs` (a bake's) have left at `now` (milliseconds since the
/// epoch).
pub fn time_left(jobs: &[JobRow], now: i64) -> TimeLeft {
    // Seconds and units of each kind's finished jobs.
    let mut pace: BTreeMap<&str, (f64, f64)> = BTreeMap::new();
    for j in jobs {
        if let (JobState::Completed, Some(start), Some(end)) =
            (j.state, j.started_at, j.finished_at)
            && j.work > 0
        {
            let e = pace.entry(j.kind.as_str()).or_default();
            e.0 += (end - start).max(0) as f64 / 1000.0;
            e.1 += j.work as f64;
        }
    }
    let mut left = 0.0;
    let mut unknown: Vec<String> = Vec::new();
    let mut running = 0usize;
    let mut any = false;
    for j in jobs {
        let waiting = matches!(
            j.state,
            JobState::Blocked | JobState::Available | JobState::Retryable | JobState::Running
        );
        if !waiting {
            continue;
        }
        any = true;
        let Some(&(seconds, units)) = pace.get(j.kind.as_str()).filter(|p| p.1 > 0.0) else {
            if !unknown.contains(&j.kind) {
                unknown.push(j.kind.clone());
            }
            continue;
        };
        let whole = j.work as f64 * seconds / units;
        left += match (j.state, j.started_at) {
            (JobState::Running, Some(start)) => {
                running += 1;
                (whole - (now - start).max(0) as f64 / 1000.0).max(0.0)
            }
            _ => whole,
        };
    }
    if !any {
        return TimeLeft::Done;
    }
    // The work left runs on as many workers as run jobs now.
    let at = left / running.max(1) as f64;
    if unknown.is_empty() {
        TimeLeft::Seconds(at)
    } else {
        TimeLeft::Unknown {
            kinds: unknown,
            at_least: at,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(kind: &str, work: i64, state: JobState, times: Option<(i64, Option<i64>)>) -> JobRow {
        JobRow {
            id: 0,
            bake_id: 1,
            index: 0,
            kind: kind.into(),
            spec: serde_json::Value::Null,
            work,
            state,
            attempts: 1,
            max_attempts: 3,
            worker: None,
            progress: 0,
            reached: 0,
            checkpoint: None,
            outputs: None,
            error: None,
            started_at: times.map(|t| t.0),
            finished_at: times.and_then(|t| t.1),
            deps: Vec::new(),
        }
    }

    #[test]
    fn each_stage_goes_at_its_own_pace() {
        use JobState::*;
        // Samples take 1 s a unit, the fit 10 s a unit; one sample of 4
        // units runs (2 s in), a fit of 2 units waits.
        let jobs = [
            job("sample", 4, Completed, Some((0, Some(4_000)))),
            job("fit", 1, Completed, Some((0, Some(10_000)))),
            job("sample", 4, Running, Some((8_000, None))),
            job("fit", 2, Blocked, None),
        ];
        assert_eq!(time_left(&jobs, 10_000), TimeLeft::Seconds(2.0 + 20.0));
        // A kind with no finished job is unknown, not free: the known
        // seconds are a floor.
        let mut tail = jobs.to_vec();
        tail.push(job("preview", 1, Blocked, None));
        assert_eq!(
            time_left(&tail, 10_000),
            TimeLeft::Unknown {
                kinds: vec!["preview".into()],
                at_least: 22.0
            }
        );
        assert!(
            time_left(&tail, 10_000)
                .to_string()
                .contains("no preview job has finished yet")
        );
        let done = [job("sample", 4, Completed, Some((0, Some(4_000))))];
        assert_eq!(time_left(&done, 10_000), TimeLeft::Done);
    }
}
