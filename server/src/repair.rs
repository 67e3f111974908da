//! Blobs the metadata names but the blob store lost (an S3 server started
//! again empty, a bucket made again, an object a lifecycle rule expired,
//! a file deleted) or whose bytes no longer hash to their name: found for
//! `retry` (which runs again the jobs whose outputs are gone) and for an
//! operator's `aobake blobs verify`, which lists every one and, with
//! `--repair`, deletes the corrupt blobs and queues done bakes that lost
//! what they serve again.

use std::collections::BTreeSet;

use crate::blobs::{BlobError, Blobs};
use crate::store::{BakeRow, BakeState, JobRow, JobState, Store, StoreError};

/// The completed jobs of a bake that must run again, given the digests
/// the blob store lost: a job whose lost output the bake serves (its
/// asset, report or plot, or any output of a job nothing depends on, such
/// as the previews), or that a job that will run reads (one not completed,
/// or one run again). Graph order, each job after its dependencies.
pub fn jobs_to_run_again(bake: &BakeRow, jobs: &[JobRow], lost: &BTreeSet<String>) -> Vec<i64> {
    let served: BTreeSet<&str> = [&bake.asset, &bake.report, &bake.plot]
        .into_iter()
        .flatten()
        .map(String::as_str)
        .collect();
    let mut order: Vec<&JobRow> = jobs.iter().collect();
    order.sort_by_key(|j| j.index);
    let at = |index: i64| order.binary_search_by_key(&index, |j| j.index).ok();
    // Whether each job (by position in `order`) will run.
    let mut runs: Vec<bool> = order
        .iter()
        .map(|j| j.state != JobState::Completed)
        .collect();
    let mut needed = vec![false; order.len()];
    let mut sink = vec![true; order.len()];
    for j in &order {
        for &d in &j.deps {
            if let Some(i) = at(d) {
                sink[i] = false;
            }
        }
    }
    // Dependents come after their dependencies: from the last job back,
    // each job knows whether anything after it that reads it will run.
    for i in (0..order.len()).rev() {
        let j = order[i];
        if j.state == JobState::Completed {
            let outputs = j.outputs.as_deref().unwrap_or_default();
            let lost_one = |served_only: bool| {
                outputs.iter().any(|o| {
                    lost.contains(&o.digest) && (!served_only || served.contains(o.digest.as_str()))
                })
            };
            runs[i] = lost_one(true) || ((sink[i] || needed[i]) && lost_one(false));
        }
        if runs[i] {
            for &d in &j.deps {
                if let Some(k) = at(d) {
                    needed[k] = true;
                }
            }
        }
    }
    order
        .iter()
        .zip(&runs)
        .filter(|(j, run)| **run && j.state == JobState::Completed)
        .map(|(j, _)| j.id)
        .collect()
}

/// The digests among the completed jobs' outputs of `jobs` that the blob
/// store no longer holds (one lookup each).
pub async fn lost_outputs(
    blobs: &dyn Blobs,
    jobs: &[JobRow],
) -> Result<BTreeSet<String>, BlobError> {
    let mut lost = BTreeSet::new();
    let digests: BTreeSet<&str> = jobs
        .iter()
        .filter(|j| j.state == JobState::Completed)
        .flat_map(|j| j.outputs.as_deref().unwrap_or_default())
        .map(|o| o.digest.as_str())
        .collect();
    for d in digests {
        if blobs.len(d).await?.is_none() {
            lost.insert(d.to_owned());
        }
    }
    Ok(lost)
}

/// What happened to one blob the metadata names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Damage {
    /// The blob store does not hold it.
    Missing,
    /// Its bytes no longer hash to its name.
    Corrupt,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // (`pad`: a width in the format string lines the findings up.)
        f.pad(match self {
            Self::Missing => "missing",
            Self::Corrupt => "corrupt",
        })
    }
}

/// One damaged blob and who names it, as `aobake blobs verify` lists it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Finding {
    /// The blob.
    pub digest: String,
    /// What happened to it.
    pub damage: Damage,
    /// Who names it: `upload character`, `bake 12 asset`, `job 40 (fit)
    /// output asset`, `job 41 checkpoint`.
    pub named_by: String,
    /// What was done about it (with `--repair`) or what to do.
    pub action: String,
    /// Whether it still needs an operator after this run (a lost upload;
    /// without repair, what repair would do).
    pub open: bool,
}

/// What a verify found and did.
#[derive(Debug, Default, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Verified {
    /// Distinct blobs looked at.
    pub blobs: usize,
    /// Bytes read and hashed.
    pub bytes: u64,
    /// Every damaged blob, in the order found.
    pub findings: Vec<Finding>,
    /// Bakes queued again (with `--repair`).
    pub requeued: Vec<i64>,
    /// Bakes `--repair` would have queued again but whose state changed
    /// while the verify ran (a retry or a cancel on the server), with
    /// why they were not: left for an operator.
    pub skipped: Vec<(i64, String)>,
}

/// Looks at every blob the store names (uploads, bakes' assets, reports
/// and plots, completed jobs' outputs, checkpoints): each read whole and
/// hashed. With `repair`: corrupt blobs are deleted (so that the next
/// `put` of the same bytes stores them again), done bakes that lost what
/// they serve are queued again with the jobs that make it (the same
/// bytes: bakes are deterministic), and checkpoints that are gone are
/// forgotten (their jobs start over). Uploads cannot be made again here:
/// a new `aobake submit` of the file uploads it.
pub async fn verify(
    store: &dyn Store,
    blobs: &dyn Blobs,
    repair: bool,
) -> Result<Verified, RepairError> {
    let mut v = Verified::default();
    let mut seen: std::collections::BTreeMap<String, Option<Damage>> = Default::default();
    // Each blob read once, however many name it.
    async fn check(
        blobs: &dyn Blobs,
        seen: &mut std::collections::BTreeMap<String, Option<Damage>>,
        v: &mut Verified,
        digest: &str,
    ) -> Result<Option<Damage>, BlobError> {
        if let Some(d) = seen.get(digest) {
            return Ok(*d);
        }
        let damage = match blobs.get(digest).await? {
            None => Some(Damage::Missing),
            Some(bytes) => {
                v.bytes += bytes.len() as u64;
                crate::blobs::verify(digest, &bytes)
                    .err()
                    .map(|_| Damage::Corrupt)
            }
        };
        v.blobs += 1;
        seen.insert(digest.to_owned(), damage);
        Ok(damage)
    }
    // Each corrupt blob deleted once: a bake queued again may have stored
    // it again, whole, by the time another names it.
    let mut deleted_once: BTreeSet<String> = BTreeSet::new();
    for u in store.uploads().await? {
        if let Some(d) = check(blobs, &mut seen, &mut v, &u.digest).await? {
            let deleted = repair
                && d == Damage::Corrupt
                && deleted_once.insert(u.digest.clone())
                && blobs.delete(&u.digest).await?;
            let action = if deleted {
                "deleted; upload the file again (`aobake submit` uploads it)"
            } else {
                "upload the file again (`aobake submit` uploads it)"
            };
            v.findings.push(Finding {
                digest: u.digest.clone(),
                damage: d,
                named_by: format!("upload {}", u.kind),
                action: action.into(),
                open: true,
            });
        }
    }
    let mut newest: std::collections::BTreeMap<String, i64> = Default::default();
    for bake in store.bakes(None, None, i64::MAX).await? {
        let jobs = store.jobs(bake.id).await?;
        let mut lost: BTreeSet<String> = BTreeSet::new();
        // (The blob, its damage, who names it, and whether that is a
        // checkpoint.)
        let mut found: Vec<(String, Damage, String, bool)> = Vec::new();
        for (name, digest) in [
            ("asset", &bake.asset),
            ("report", &bake.report),
            ("plot", &bake.plot),
        ] {
            if let Some(digest) = digest
                && let Some(d) = check(blobs, &mut seen, &mut v, digest).await?
            {
                lost.insert(digest.clone());
                found.push((digest.clone(), d, format!("bake {} {name}", bake.id), false));
            }
        }
        let mut checkpoints = Vec::new();
        for j in &jobs {
            for o in j.outputs.as_deref().unwrap_or_default() {
                if let Some(d) = check(blobs, &mut seen, &mut v, &o.digest).await? {
                    lost.insert(o.digest.clone());
                    found.push((
                        o.digest.clone(),
                        d,
                        format!("job {} ({}) output {}", j.id, j.kind, o.name),
                        false,
                    ));
                }
            }
            if j.state != JobState::Completed
                && let Some(cp) = &j.checkpoint
                && let Some(d) = check(blobs, &mut seen, &mut v, &cp.blob).await?
            {
                checkpoints.push((j.id, cp.blob.clone()));
                found.push((
                    cp.blob.clone(),
                    d,
                    format!("job {} ({}) checkpoint", j.id, j.kind),
                    true,
                ));
            }
        }
        let again = jobs_to_run_again(&bake, &jobs, &lost);
        // Bakes come newest first: a newer bake of the same key that
        // serves (or will) makes an older one's loss moot.
        let newer = newest.get(&bake.key).copied();
        // (Whether `--repair` queues it, with or without the flag, so that
        // a run without it says what a run with it does.)
        let queues = bake.state == BakeState::Done && !again.is_empty() && newer.is_none();
        let requeue = repair && queues;
        if bake.state.is_active() || (bake.state == BakeState::Done && (again.is_empty() || queues))
        {
            newest.entry(bake.key.clone()).or_insert(bake.id);
        }
        if found.is_empty() {
            continue;
        }
        let superseded = newer
            .map(|n| format!("not needed: bake {n} with the same key serves it"))
            .unwrap_or_default();
        for (digest, d, named_by, checkpoint) in found {
            let deleted = repair
                && d == Damage::Corrupt
                && deleted_once.insert(digest.clone())
                && blobs.delete(&digest).await?;
            // (What it says, and whether an operator must still act.)
            let (what, open) = if checkpoint {
                if repair {
                    ("forgotten: the job starts over", false)
                } else {
                    ("the job starts over", d == Damage::Corrupt)
                }
            } else {
                match (bake.state, requeue) {
                    (_, true) => ("the bake is queued again to make it", false),
                    (BakeState::Done, false) if newer.is_some() && !again.is_empty() => {
                        (superseded.as_str(), d == Damage::Corrupt && !repair)
                    }
                    (BakeState::Done, false) if again.is_empty() => (
                        "not needed: the bake serves what it made without it",
                        d == Damage::Corrupt && !repair,
                    ),
                    (BakeState::Done, false) => {
                        ("`--repair` queues the bake again to make it", true)
                    }
                    (BakeState::Failed | BakeState::Cancelled, _) => (
                        "`aobake retry` runs its job again",
                        d == Damage::Corrupt && !repair,
                    ),
                    _ => (
                        "the bake's jobs that read it will fail; `aobake retry` then runs it again",
                        d == Damage::Corrupt && !repair,
                    ),
                }
            };
            v.findings.push(Finding {
                digest,
                damage: d,
                named_by,
                action: if deleted {
                    format!("deleted; {what}")
                } else {
                    what.to_owned()
                },
                open,
            });
        }
        if repair {
            for (job, blob) in checkpoints {
                store.forget_checkpoint(job, &blob).await?;
            }
        }
        if requeue {
            match store.retry(bake.id, &again).await {
                Ok(_) => v.requeued.push(bake.id),
                // Its state changed since it was read (a retry, a cancel
                // on the server): said, and the other bakes still checked.
                Err(StoreError::Conflict(why)) => v.skipped.push((bake.id, why)),
                Err(e) => return Err(e.into()),
            }
        }
    }
    Ok(v)
}

/// Why a verify stopped.
#[derive(Debug, thiserror::Error)]
pub enum RepairError {
    /// The blob store failed.
    #[error(transparent)]
    Blobs(#[from] BlobError),
    /// The database failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::OutputRef;

    fn job(id: i64, index: i64, deps: &[i64], outputs: &[&str], state: JobState) -> JobRow {
        JobRow {
            id,
            bake_id: 1,
            index,
            kind: "k".into(),
            spec: serde_json::Value::Null,
            work: 1,
            state,
            attempts: 1,
            max_attempts: 3,
            worker: None,
            progress: 0,
            reached: 0,
            checkpoint: None,
            outputs: Some(
                outputs
                    .iter()
                    .map(|d| OutputRef {
                        name: format!("out-{d}"),
                        digest: (*d).into(),
                    })
                    .collect(),
            ),
            error: None,
            started_at: None,
            finished_at: None,
            deps: deps.to_vec(),
        }
    }

    #[test]
    fn only_jobs_whose_lost_outputs_are_served_or_read_run_again() {
        use JobState::{Completed as C, Dead};
        let bake = |asset: &str| BakeRow {
            id: 1,
            key: String::new(),
            character: String::new(),
            clips: vec![],
            method: String::new(),
            params: serde_json::Value::Null,
            state: BakeState::Done,
            priority: 0,
            total_work: 5,
            done_work: 5,
            running_work: 0,
            redo_work: 0,
            jobs_total: 5,
            jobs_done: 5,
            asset: Some(asset.into()),
            report: None,
            plot: None,
            error: None,
            created_at: 0,
            updated_at: 0,
            finished_at: None,
        };
        // Two samples (a, b) → fit (asset f) → preview (p); c read by nothing
        // but the fit, which is done.
        let jobs = |fit: JobState, preview: JobState| {
            vec![
                job(10, 0, &[], &["a"], C),
                job(11, 1, &[], &["b"], C),
                job(12, 2, &[0, 1], &["f"], fit),
                job(13, 3, &[2], &["p"], preview),
            ]
        };
        let lost = |ds: &[&str]| ds.iter().map(|d| (*d).to_owned()).collect();
        let done = jobs(C, C);
        // A sample's output lost, the asset served: nothing runs again.
        assert!(jobs_to_run_again(&bake("f"), &done, &lost(&["a"])).is_empty());
        // The asset lost: the fit runs again, and so the samples it reads
        // that were lost (a), not those still held (b).
        assert_eq!(
            jobs_to_run_again(&bake("f"), &done, &lost(&["f", "a"])),
            [10, 12]
        );
        // The previews (nothing reads them) lost: the preview job.
        assert_eq!(jobs_to_run_again(&bake("f"), &done, &lost(&["p"])), [13]);
        // A failed bake whose preview died: the fit's lost asset runs again
        // as the preview reads it, and a lost sample only if the fit runs.
        let failed = jobs(C, Dead);
        assert_eq!(jobs_to_run_again(&bake("x"), &failed, &lost(&["f"])), [12]);
        assert!(jobs_to_run_again(&bake("x"), &failed, &lost(&["a"])).is_empty());
        assert_eq!(
            jobs_to_run_again(&bake("x"), &jobs(Dead, Dead), &lost(&["a"])),
            [10]
        );
    }
}
