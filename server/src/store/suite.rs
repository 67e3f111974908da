//! The store's behaviour, written once and run against every backend
//! (each backend's test module calls [`run_all`] on a fresh store).

use serde_json::json;

use super::{
    Action, BakeState, CheckpointRef, Completion, JobState, NewBake, NewJob, OutputRef,
    QueuePolicy, Store, StoreError, UploadRow,
};

fn policy() -> QueuePolicy {
    QueuePolicy {
        lease_ms: 60_000,
        backoff_ms: 1,
        max_backoff_ms: 2,
        worker_failures: 100,
        max_attempts: 2,
    }
}

async fn character(store: &dyn Store) -> String {
    let digest = "c".repeat(64);
    store
        .put_upload(&UploadRow {
            digest: digest.clone(),
            kind: "character".into(),
            bundle: false,
            bytes: 1,
            summary: json!({}),
        })
        .await
        .unwrap();
    digest
}

/// Two samples → fit: the diamond every vertex bake has, in small.
fn bake(character: &str, key: &str) -> NewBake {
    let job = |kind: &str, deps: Vec<usize>| NewJob {
        kind: kind.into(),
        spec: json!({"kind": kind}),
        work: 2,
        deps,
    };
    NewBake {
        key: key.into(),
        character: character.into(),
        clips: vec![],
        method: "vertex-linear".into(),
        params: json!({}),
        priority: 0,
        jobs: vec![
            job("sample", vec![]),
            job("sample", vec![]),
            job("fit", vec![0, 1]),
        ],
        max_attempts: 2,
    }
}

/// The first of the key's bakes (a done one before an active one).
async fn first_for_key(store: &dyn Store, key: &str) -> super::BakeRow {
    let bakes = store.bakes_for_key(key).await.unwrap();
    bakes.into_iter().next().expect("a bake with the key")
}

fn done(name: &str) -> Completion {
    Completion {
        outputs: vec![OutputRef {
            name: name.into(),
            digest: "d".repeat(64),
        }],
        timings: json!({"fit_s": 1.0}),
    }
}

/// Runs every case. `store` must be new: the first case needs a store
/// that has seen no worker.
pub(crate) async fn run_all(store: &dyn Store) {
    a_lone_worker_is_never_kept_off(store).await;
    uploads_are_idempotent(store).await;
    jobs_run_in_dependency_order_and_publish_the_asset(store).await;
    stale_tokens_are_refused(store).await;
    failures_retry_then_kill_the_bake(store).await;
    cancel_pause_resume_retry(store).await;
    progress_only_moves_forward_and_lost_outputs_run_again(store).await;
    a_retry_takes_back_the_jobs_a_failed_bake_still_ran(store).await;
    a_worker_that_keeps_failing_a_bake_is_kept_off_it(store).await;
    tracing_jobs_wait_for_a_waiting_gpu_worker_not_for_a_busy_one(store).await;
    a_stopped_worker_is_listed_so_at_once_and_holds_no_job_back(store).await;
    a_lease_request_sent_again_gets_what_it_leased(store).await;
    a_worker_started_again_under_its_name_is_listed_as_started_then(store).await;
    a_batch_leases_a_job_per_slot_and_completes_each_on_its_own(store).await;
    a_batch_split_by_failures_leases_each_job_once(store).await;
    tokens_are_listed_newest_first_and_deleted(store).await;
    tokens_expire_and_record_their_use(store).await;
    // Last: it forgets every other case's idle workers.
    workers_gone_for_long_are_forgotten_unless_they_hold_a_job(store).await;
}

/// Workers not seen for long leave the list, except one still holding a
/// running job; one seen lately stays.
async fn workers_gone_for_long_are_forgotten_unless_they_hold_a_job(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"a".repeat(64));
    b.priority = 4000;
    let created = store.create_bake(&b).await.unwrap();
    let held = store.lease("holder", &policy()).await.unwrap().unwrap();
    assert_eq!(held.job.bake_id, created.id);
    store.workers_idle(&["gone".to_owned()]).await.unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(600)).await;
    store.workers_idle(&["fresh".to_owned()]).await.unwrap();
    assert!(store.forget_workers(300).await.unwrap() >= 1);
    let listed: Vec<String> = store
        .workers(60_000)
        .await
        .unwrap()
        .into_iter()
        .map(|w| w.id)
        .collect();
    assert!(listed.contains(&"holder".to_owned()), "{listed:?}");
    assert!(listed.contains(&"fresh".to_owned()), "{listed:?}");
    assert!(!listed.contains(&"gone".to_owned()), "{listed:?}");
    store.control(created.id, Action::Cancel).await.unwrap();
}

/// A token keeps its expiry (the caller judges it) and records its use.
async fn tokens_expire_and_record_their_use(store: &dyn Store) {
    let hash = "9".repeat(64);
    store
        .create_token_until(&hash, "brief", &["read".into()], Some(1_000))
        .await
        .unwrap();
    let row = store.token(&hash).await.unwrap().unwrap();
    assert_eq!((row.expires_at, row.last_used_at), (Some(1_000), None));
    // Recorded at most once a minute.
    for (at, kept) in [(100_000, 100_000), (130_000, 100_000), (160_000, 160_000)] {
        store.token_used(&hash, at).await.unwrap();
        let row = store.token(&hash).await.unwrap().unwrap();
        assert_eq!(row.last_used_at, Some(kept), "used at {at}");
    }
    // Made again (a server starting with the same secret), its expiry
    // stays: a restart does not revive an expired token.
    store
        .create_token_until(&hash, "brief", &["read".into()], None)
        .await
        .unwrap();
    let row = store.token(&hash).await.unwrap().unwrap();
    assert_eq!(row.expires_at, Some(1_000));
    let listed = store.tokens().await.unwrap();
    let (_, listed) = listed.iter().find(|(h, _)| *h == hash).unwrap();
    assert_eq!(listed, &row);
    assert!(store.delete_token(&hash, true).await.unwrap());
}

async fn tokens_are_listed_newest_first_and_deleted(store: &dyn Store) {
    let before = store.tokens().await.unwrap().len();
    store
        .create_token(&"1".repeat(64), "ci", &["read".into(), "submit".into()])
        .await
        .unwrap();
    // Another millisecond on the database's clock: newest first.
    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    store
        .create_token(&"2".repeat(64), "farm", &["worker".into()])
        .await
        .unwrap();
    let listed = store.tokens().await.unwrap();
    assert_eq!(listed.len(), before + 2);
    let (newest, row) = &listed[0];
    assert_eq!(
        (newest.as_str(), row.name.as_str()),
        ("2".repeat(64).as_str(), "farm")
    );
    let ci = &listed[1].1;
    assert_eq!(ci.scopes, ["read", "submit"]);
    assert!(ci.created_at > 1_600_000_000_000 && ci.created_at <= row.created_at);
    assert!(store.delete_token(&"1".repeat(64), true).await.unwrap());
    assert!(
        !store.delete_token(&"1".repeat(64), true).await.unwrap(),
        "gone"
    );
    assert_eq!(store.token(&"1".repeat(64)).await.unwrap(), None);
    assert!(store.token(&"2".repeat(64)).await.unwrap().is_some());
    // A revoked secret stays revoked: creating it again (a server started
    // with it as its admin token) is refused, and it stays unknown.
    let again = store
        .create_token(&"1".repeat(64), "admin", &["admin".into()])
        .await;
    assert!(
        matches!(again, Err(StoreError::Revoked(at)) if at >= ci.created_at),
        "{again:?}"
    );
    assert_eq!(store.token(&"1".repeat(64)).await.unwrap(), None);
    // A token only deleted (serve rotating its own out) may come back; an
    // unknown one revoked is not recorded.
    assert!(store.delete_token(&"2".repeat(64), false).await.unwrap());
    store
        .create_token(&"2".repeat(64), "farm", &["worker".into()])
        .await
        .unwrap();
    assert!(store.token(&"2".repeat(64)).await.unwrap().is_some());
    assert!(!store.delete_token(&"3".repeat(64), true).await.unwrap());
    store
        .create_token(&"3".repeat(64), "ci", &["read".into()])
        .await
        .unwrap();
    assert!(store.token(&"3".repeat(64)).await.unwrap().is_some());
}

/// A slot with failures on record claims apart from the others (its own
/// bakes to be kept off); the jobs it claimed must not go to the others
/// too.
async fn a_batch_split_by_failures_leases_each_job_once(store: &dyn Store) {
    let c = character(store).await;
    let p = QueuePolicy {
        worker_failures: 1,
        ..policy()
    };
    // One failure on another bake puts slot 0 in a group of its own.
    let mut other = bake(&c, &"e".repeat(64));
    other.priority = 4000;
    let other = store.create_bake(&other).await.unwrap();
    let l = store.lease("split/0", &p).await.unwrap().unwrap();
    assert_eq!(l.job.bake_id, other.id);
    store
        .fail(l.job.id, &l.token, "oops", true, &p)
        .await
        .unwrap();
    store.control(other.id, Action::Cancel).await.unwrap();
    let mut b = bake(&c, &"f".repeat(64));
    b.priority = 5000;
    let b = store.create_bake(&b).await.unwrap();
    let slots: Vec<String> = (0..3).map(|i| format!("split/{i}")).collect();
    let leases = store.lease_many(&slots, &p).await.unwrap();
    let ids: std::collections::BTreeSet<i64> = leases.iter().map(|l| l.job.id).collect();
    assert_eq!(ids.len(), leases.len(), "a job leased twice: {leases:?}");
    // The bake's two ready jobs, once each (a third slot may get an
    // earlier case's job).
    let ours: Vec<_> = leases.iter().filter(|l| l.job.bake_id == b.id).collect();
    assert_eq!(ours.len(), 2, "{leases:?}");
    assert!(ours.iter().all(|l| l.job.attempts == 1), "{leases:?}");
    for l in &leases {
        store.release(l.job.id, &l.token).await.unwrap();
    }
    let twice = store
        .lease_many(&["split/0".to_owned(), "split/0".to_owned()], &p)
        .await;
    assert!(matches!(twice, Err(StoreError::Conflict(_))), "{twice:?}");
    // Idle slots are marked in one go, a repeated one once; a busy one
    // (split/1, holding a job now) and a new one too.
    let held = store.lease("split/1", &p).await.unwrap().unwrap();
    let busy = store.workers(60_000).await.unwrap();
    let before = busy.iter().find(|w| w.id == "split/1").unwrap();
    assert_eq!(
        (before.state.as_str(), before.job_id, before.bake_id),
        ("busy", Some(held.job.id), Some(held.job.bake_id))
    );
    let idle = ["split/0", "split/1", "split/0", "split/new"].map(str::to_owned);
    store.workers_idle(&idle).await.unwrap();
    let workers = store.workers(60_000).await.unwrap();
    for id in ["split/0", "split/1", "split/new"] {
        let w = workers.iter().find(|w| w.id == id).unwrap();
        assert_eq!((w.state.as_str(), w.job_id), ("idle", None), "{w:?}");
    }
    // A worker not seen for the given time is listed as stopped, with no
    // job, whatever it last said (the row itself is kept as it was).
    store.release(held.job.id, &held.token).await.unwrap();
    let held = store.lease("split/1", &p).await.unwrap().unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    let gone = store.workers(5).await.unwrap();
    let busy = store.workers(60_000).await.unwrap();
    for id in ["split/0", "split/1", "split/new"] {
        let w = gone.iter().find(|w| w.id == id).unwrap();
        assert_eq!((w.state.as_str(), w.job_id), ("stopped", None), "{w:?}");
    }
    let w = busy.iter().find(|w| w.id == "split/1").unwrap();
    assert_eq!((w.state.as_str(), w.job_id), ("busy", Some(held.job.id)));
    // A slot whose job stopped running without it (its bake cancelled:
    // the worker's release is refused) is idle at once, not busy until
    // its next poll.
    store
        .control(held.job.bake_id, Action::Cancel)
        .await
        .unwrap();
    let after = store.workers(60_000).await.unwrap();
    let w = after.iter().find(|w| w.id == "split/1").unwrap();
    assert_eq!((w.state.as_str(), w.job_id), ("idle", None), "{w:?}");
}

/// With no other worker to take its jobs, a failing worker goes on
/// getting them until their attempts run out, so the bake fails with the
/// reason instead of waiting forever.
async fn a_lone_worker_is_never_kept_off(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"7".repeat(64));
    b.max_attempts = 4;
    let created = store.create_bake(&b).await.unwrap();
    let p = QueuePolicy {
        worker_failures: 1,
        ..policy()
    };
    // A worker that stopped and said so is not one to wait for.
    store.workers_idle(&["leaver".to_owned()]).await.unwrap();
    store.workers_stopped(&["leaver".to_owned()]).await.unwrap();
    for attempt in 1..=4 {
        let l = store.lease("alone", &p).await.unwrap();
        let l = l.unwrap_or_else(|| panic!("attempt {attempt}: the lone worker was kept off"));
        store
            .fail(l.job.id, &l.token, "broken", true, &p)
            .await
            .unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    let end = store.bake(created.id).await.unwrap().unwrap();
    assert_eq!(end.state, BakeState::Failed);
}

async fn a_worker_that_keeps_failing_a_bake_is_kept_off_it(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"6".repeat(64));
    b.priority = 1000;
    b.max_attempts = 10;
    let created = store.create_bake(&b).await.unwrap();
    let p = QueuePolicy {
        worker_failures: 2,
        ..policy()
    };
    for _ in 0..2 {
        let l = store.lease("clumsy", &p).await.unwrap().unwrap();
        assert_eq!(l.job.bake_id, created.id);
        store
            .fail(l.job.id, &l.token, "oops", true, &p)
            .await
            .unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    // Kept off this bake (other bakes' jobs may still come its way).
    while let Some(l) = store.lease("clumsy", &p).await.unwrap() {
        assert_ne!(
            l.job.bake_id, created.id,
            "a banned worker got the bake's job"
        );
        store
            .complete(l.job.id, &l.token, &done("ao"))
            .await
            .unwrap();
    }
    // In one batch with a worker that may take the bake, each is judged
    // on its own: the careful slot gets the bake's job, the clumsy none.
    let batch = store
        .lease_many(&["clumsy".to_owned(), "careful".to_owned()], &p)
        .await
        .unwrap();
    assert_eq!(batch.len(), 1, "{batch:?}");
    assert_eq!(batch[0].job.worker.as_deref(), Some("careful"));
    assert_eq!(batch[0].job.bake_id, created.id);
}

/// A batch leases at most one job per slot, in the slots' order; its
/// completions are judged one by one (a stale token refuses only its own),
/// and a dependent whose dependencies complete in one batch counts them
/// all.
async fn a_batch_leases_a_job_per_slot_and_completes_each_on_its_own(store: &dyn Store) {
    let c = character(store).await;
    let job = |kind: &str, deps: Vec<usize>| NewJob {
        kind: kind.into(),
        spec: json!({"kind": kind}),
        work: 3,
        deps,
    };
    let b = store
        .create_bake(&NewBake {
            key: "b".repeat(64),
            character: c.clone(),
            clips: vec![],
            method: "vertex-linear".into(),
            params: json!({}),
            priority: 3000,
            jobs: vec![
                job("sample", vec![]),
                job("sample", vec![]),
                job("sample", vec![]),
                job("fit", vec![0, 1, 2]),
            ],
            max_attempts: 2,
        })
        .await
        .unwrap();
    let p = policy();
    let slots: Vec<String> = (0..3).map(|i| format!("proc/{i}")).collect();
    let leases = store.lease_many(&slots, &p).await.unwrap();
    let got: Vec<_> = leases
        .iter()
        .map(|l| (l.job.bake_id, l.job.index, l.job.worker.clone().unwrap()))
        .collect();
    assert_eq!(
        got,
        (0..3)
            .map(|i| (b.id, i as i64, slots[i].clone()))
            .collect::<Vec<_>>()
    );
    assert!(leases.iter().all(|l| l.uploads[0].digest == c));
    let tokens: std::collections::BTreeSet<_> = leases.iter().map(|l| &l.token).collect();
    assert_eq!(tokens.len(), 3, "every lease has its own token");
    let item = |l: &super::Lease, token: &str| super::JobCompletion {
        job: l.job.id,
        token: token.to_owned(),
        completion: done("ao"),
    };
    let answers = store
        .complete_many(&[
            item(&leases[0], &leases[0].token),
            item(&leases[1], "stale"),
            item(&leases[2], &leases[2].token),
            item(&leases[0], &leases[0].token),
        ])
        .await
        .unwrap();
    let lost = |r: &super::Result<super::BakeRow>| matches!(r, Err(StoreError::LeaseLost(_)));
    assert!(answers[0].is_ok() && answers[2].is_ok(), "{answers:?}");
    assert!(lost(&answers[1]), "{answers:?}");
    let mid = answers[0].as_ref().unwrap();
    assert_eq!((mid.jobs_done, mid.done_work), (2, 6));
    assert_eq!(answers[2].as_ref().unwrap(), mid);
    // A completion sent twice is answered twice and counted once.
    assert_eq!(answers[3].as_ref().unwrap(), mid);
    // Two of the fit's three dependencies completed in that batch.
    let waiting = store.lease_many(&slots[..1], &p).await.unwrap();
    assert!(
        waiting.iter().all(|l| l.job.bake_id != b.id),
        "the fit waits for its third dependency: {waiting:?}"
    );
    for l in &waiting {
        store.release(l.job.id, &l.token).await.unwrap();
    }
    store
        .complete(leases[1].job.id, &leases[1].token, &done("ao"))
        .await
        .unwrap();
    let fit = store.lease_many(&slots, &p).await.unwrap();
    assert_eq!((fit[0].job.bake_id, fit[0].job.index), (b.id, 3));
    assert_eq!(fit[0].inputs.len(), 3);
    let end = store
        .complete_many(&[item(&fit[0], &fit[0].token)])
        .await
        .unwrap();
    assert_eq!(end[0].as_ref().unwrap().state, BakeState::Done);
    // Each job says when it was leased and when it completed: the
    // clients' estimates of the time left are made of them.
    assert!(
        leases.iter().all(|l| l.job.started_at.is_some()),
        "{leases:?}"
    );
    let jobs = store.jobs(b.id).await.unwrap();
    assert!(
        jobs.iter().all(|j| matches!(
            (j.started_at, j.finished_at),
            (Some(s), Some(f)) if f >= s
        )),
        "{jobs:?}"
    );
    for l in &fit[1..] {
        store.release(l.job.id, &l.token).await.unwrap();
    }
    let workers = store.workers(60_000).await.unwrap();
    let state = |id: &str| workers.iter().find(|w| w.id == id).unwrap().state.clone();
    assert_eq!(state("proc/0"), "idle");
}

async fn tracing_jobs_wait_for_a_waiting_gpu_worker_not_for_a_busy_one(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"5".repeat(64));
    b.priority = 2000;
    let created = store.create_bake(&b).await.unwrap();
    let p = policy();
    store.worker_tracer("gpu", "gpu: an adapter").await.unwrap();
    store.workers_idle(&["gpu".to_owned()]).await.unwrap();
    store.worker_tracer("cpu", "cpu").await.unwrap();
    // A GPU worker is waiting: the CPU worker leaves the samples to it
    // (and may take another bake's work).
    if let Some(l) = store.lease("cpu", &p).await.unwrap() {
        assert_ne!(l.job.bake_id, created.id, "{:?}", l.job);
        store
            .complete(l.job.id, &l.token, &done("x"))
            .await
            .unwrap();
    }
    let first = store.lease("gpu", &p).await.unwrap().unwrap();
    assert_eq!(
        (first.job.bake_id, first.job.kind.as_str()),
        (created.id, "sample")
    );
    // Now it is busy: the CPU worker is not held up.
    let second = store.lease("cpu", &p).await.unwrap().unwrap();
    assert_eq!(
        (second.job.bake_id, second.job.kind.as_str()),
        (created.id, "sample")
    );
    let workers = store.workers(60_000).await.unwrap();
    let tracer = |id: &str| workers.iter().find(|w| w.id == id).unwrap().tracer.clone();
    assert_eq!(
        (tracer("gpu").as_str(), tracer("cpu").as_str()),
        ("gpu: an adapter", "cpu")
    );
}

/// A worker process that says it stopped is listed as stopped at once,
/// with no job (not a lease later), and an idle GPU worker that stopped
/// holds no tracing job back from CPU workers; polling again revives it.
async fn a_stopped_worker_is_listed_so_at_once_and_holds_no_job_back(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"8".repeat(64));
    b.priority = 3000;
    let created = store.create_bake(&b).await.unwrap();
    let p = policy();
    let leaving = ["gpu/0".to_owned(), "gpu/1".to_owned()];
    for w in &leaving {
        store.worker_tracer(w, "gpu: an adapter").await.unwrap();
    }
    store.workers_idle(&leaving).await.unwrap();
    store.worker_tracer("cpu/0", "cpu").await.unwrap();
    store.workers_stopped(&leaving).await.unwrap();
    // A poll that was open when they stopped does not mark them waiting
    // again.
    assert!(!store.workers_still_waiting(&leaving).await.unwrap());
    let workers = store.workers(60_000).await.unwrap();
    for id in &leaving {
        let w = workers.iter().find(|w| &w.id == id).unwrap();
        assert_eq!((w.state.as_str(), w.job_id), ("stopped", None), "{w:?}");
    }
    let l = store.lease("cpu/0", &p).await.unwrap().unwrap();
    assert_eq!(
        (l.job.bake_id, l.job.kind.as_str()),
        (created.id, "sample"),
        "a stopped GPU worker held the tracing job back"
    );
    // No lease goes to a stopped slot (a poll open as it stopped), and a
    // job leased to a slot as it stopped is given back, its attempt not
    // counted.
    let batch = store.lease_many(&leaving, &p).await.unwrap();
    assert!(batch.is_empty(), "{batch:?}");
    store.workers_stopped(&["cpu/0".to_owned()]).await.unwrap();
    let again = store.lease("cpu/1", &p).await.unwrap().unwrap();
    assert_eq!(
        (again.job.id, again.job.attempts),
        (l.job.id, 1),
        "the stopped slot's job, given back"
    );
    store.workers_idle(&leaving[..1]).await.unwrap();
    assert!(store.workers_still_waiting(&leaving[..1]).await.unwrap());
    let workers = store.workers(60_000).await.unwrap();
    let w = workers.iter().find(|w| w.id == "gpu/0").unwrap();
    assert_eq!(w.state, "idle", "{w:?}");
    // The cases after this one lease their own bakes' jobs, on CPU
    // workers.
    store.workers_stopped(&leaving).await.unwrap();
    store.control(created.id, Action::Cancel).await.unwrap();
}

/// The same lease request sent again after its answer was lost (a server
/// that died after committing it) gets the job it leased, same token,
/// same attempt, lease renewed, beside new jobs for its other slots;
/// another request naming the same slot (another process under the same
/// id, or this one after an answer) does not.
async fn a_lease_request_sent_again_gets_what_it_leased(store: &dyn Store) {
    let c = character(store).await;
    let mut b = bake(&c, &"9".repeat(64));
    b.priority = 3001;
    let created = store.create_bake(&b).await.unwrap();
    let mut p = policy();
    p.lease_ms = 1_000;
    let slots = ["lost/0".to_owned(), "lost/1".to_owned()];
    let lost = store
        .lease_batch(&slots[..1], Some("first"), &p)
        .await
        .unwrap()
        .remove(0);
    assert_eq!(lost.job.bake_id, created.id);
    p.lease_ms = 60_000;
    let batch = store.lease_batch(&slots, Some("first"), &p).await.unwrap();
    assert_eq!(batch.len(), 2, "{batch:?}");
    let (again, other) = (&batch[0], &batch[1]);
    assert_eq!(
        (again.job.id, again.token.as_str(), again.job.attempts),
        (lost.job.id, lost.token.as_str(), 1),
        "the lost lease, answered again"
    );
    assert!(again.expires_at >= lost.expires_at + 30_000, "{again:?}");
    assert_eq!(again.job.worker.as_deref(), Some("lost/0"));
    assert_ne!(other.job.id, lost.job.id);
    assert_eq!(other.job.worker.as_deref(), Some("lost/1"));
    // The first request's give-back (its client gone) keeps a lease that
    // was renewed since: the job still runs under its token.
    store
        .release_unless_renewed(lost.job.id, &lost.token, Some(lost.expires_at))
        .await
        .unwrap();
    store
        .heartbeat(lost.job.id, &lost.token, 1, &p)
        .await
        .expect("still leased");
    // Another request under the same slot's name is not given them.
    for l in store
        .lease_batch(&slots[..1], Some("second"), &p)
        .await
        .unwrap()
    {
        assert!(l.job.id != lost.job.id && l.job.id != other.job.id, "{l:?}");
        store.release(l.job.id, &l.token).await.unwrap();
    }
    // The lease it renewed is the one it holds: the jobs complete.
    for l in [again, other] {
        store
            .complete(l.job.id, &l.token, &done("samples"))
            .await
            .unwrap();
    }
    store.control(created.id, Action::Cancel).await.unwrap();
}

/// A process tells its tracer once, as it starts: one that starts again
/// under a name used before (`aobake serve` restarting a local worker) is
/// listed as started then, not at the first start.
async fn a_worker_started_again_under_its_name_is_listed_as_started_then(store: &dyn Store) {
    let started = |workers: Vec<super::WorkerRow>| {
        workers
            .into_iter()
            .find(|w| w.id == "again")
            .map(|w| w.started_at)
            .unwrap()
    };
    store.worker_tracer("again", "cpu").await.unwrap();
    let first = started(store.workers(60_000).await.unwrap());
    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    store.workers_idle(&["again".to_owned()]).await.unwrap();
    assert_eq!(started(store.workers(60_000).await.unwrap()), first);
    store.worker_tracer("again", "cpu").await.unwrap();
    assert!(started(store.workers(60_000).await.unwrap()) > first);
    store.workers_stopped(&["again".to_owned()]).await.unwrap();
}

async fn uploads_are_idempotent(store: &dyn Store) {
    let d = character(store).await;
    assert!(
        !store
            .put_upload(&store.upload(&d, "character").await.unwrap().unwrap())
            .await
            .unwrap()
    );
    assert!(
        store
            .upload(&"e".repeat(64), "character")
            .await
            .unwrap()
            .is_none()
    );
    // The same bytes as clips are another upload.
    assert!(store.upload(&d, "clips").await.unwrap().is_none());
    let mut as_clips = store.upload(&d, "character").await.unwrap().unwrap();
    as_clips.kind = "clips".into();
    assert!(store.put_upload(&as_clips).await.unwrap());
    assert_eq!(
        store.upload(&d, "clips").await.unwrap().unwrap().kind,
        "clips"
    );
}

async fn jobs_run_in_dependency_order_and_publish_the_asset(store: &dyn Store) {
    let c = character(store).await;
    let b = store.create_bake(&bake(&c, &"1".repeat(64))).await.unwrap();
    assert_eq!(
        (b.state, b.total_work, b.jobs_total),
        (BakeState::Queued, 6, 3)
    );
    let p = policy();
    let a = store.lease("w1", &p).await.unwrap().unwrap();
    let b2 = store.lease("w2", &p).await.unwrap().unwrap();
    assert_eq!((a.job.index, b2.job.index), (0, 1));
    assert!(store.lease("w3", &p).await.unwrap().is_none(), "fit waits");
    assert_eq!(a.job.attempts, 1);
    let beat = store.heartbeat(a.job.id, &a.token, 1, &p).await.unwrap();
    assert!(!beat.stop && beat.moved);
    assert_eq!(beat.bake.id, a.job.bake_id);
    // The running job's progress is the bake's running work, wherever the
    // bake's row is read: what its events and its view's bar show.
    assert_eq!((beat.bake.done_work, beat.bake.running_work), (0, 1));
    let read = store.bake(b.id).await.unwrap().unwrap();
    let listed = store.bakes(Some(&c), None, 10).await.unwrap();
    let by_key = first_for_key(store, &"1".repeat(64)).await;
    for row in [
        &read,
        &by_key,
        listed.iter().find(|l| l.id == b.id).unwrap(),
    ] {
        assert_eq!(row.running_work, 1, "{row:?}");
    }
    // The same progress again: nothing moved.
    let beat = store.heartbeat(a.job.id, &a.token, 1, &p).await.unwrap();
    assert!(!beat.stop && !beat.moved);
    store
        .checkpoint(
            a.job.id,
            &a.token,
            &CheckpointRef {
                step: "sample".into(),
                cursor: 1,
                blob: "e".repeat(64),
            },
        )
        .await
        .unwrap();
    // A completion's row has the other running job's progress, and the
    // finished job's work counted once, as done.
    store.heartbeat(b2.job.id, &b2.token, 1, &p).await.unwrap();
    let first = store
        .complete(a.job.id, &a.token, &done("ao"))
        .await
        .unwrap();
    assert_eq!((first.done_work, first.running_work), (2, 1));
    let mid = store
        .complete(b2.job.id, &b2.token, &done("ao"))
        .await
        .unwrap();
    assert_eq!((mid.done_work, mid.jobs_done, mid.running_work), (4, 2, 0));
    let fit = store.lease("w1", &p).await.unwrap().unwrap();
    assert_eq!(fit.job.index, 2);
    assert_eq!(fit.inputs.len(), 2, "one entry per dependency");
    assert_eq!(fit.inputs[0].outputs[0].name, "ao");
    assert_eq!(fit.uploads[0].digest, c);
    let end = store
        .complete(fit.job.id, &fit.token, &done("asset"))
        .await
        .unwrap();
    assert_eq!(end.state, BakeState::Done);
    assert_eq!(end.asset.as_deref(), Some("d".repeat(64).as_str()));
    let found = first_for_key(store, &"1".repeat(64)).await;
    assert_eq!(found.id, end.id);
    let jobs = store.jobs(end.id).await.unwrap();
    assert!(jobs.iter().all(|j| j.state == JobState::Completed));
    assert_eq!(jobs[2].deps, [0, 1]);
    assert_eq!(jobs[0].checkpoint.as_ref().unwrap().cursor, 1);
    let listed = store
        .bakes(Some(&c), Some("vertex-linear"), 10)
        .await
        .unwrap();
    assert!(listed.iter().any(|b| b.id == end.id));
}

async fn stale_tokens_are_refused(store: &dyn Store) {
    let c = character(store).await;
    let b = store.create_bake(&bake(&c, &"2".repeat(64))).await.unwrap();
    let mut p = policy();
    p.lease_ms = 1;
    let first = store.lease("slow", &p).await.unwrap().unwrap();
    assert_eq!(first.job.bake_id, b.id);
    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    assert!(store.reap().await.unwrap() >= 1);
    let again = store.lease("fast", &policy()).await.unwrap().unwrap();
    assert_eq!(
        again.job.id, first.job.id,
        "the expired job is leased again"
    );
    assert_eq!(again.job.attempts, 2);
    for r in [
        store
            .complete(first.job.id, &first.token, &done("ao"))
            .await
            .map(|_| ()),
        store
            .heartbeat(first.job.id, &first.token, 0, &p)
            .await
            .map(|_| ()),
    ] {
        assert!(matches!(r, Err(StoreError::LeaseLost(_))), "{r:?}");
    }
    // Refused operations roll their transactions back: more refusals than
    // the pool has connections leave every connection usable.
    for _ in 0..40 {
        let refused = store
            .complete(first.job.id, &first.token, &done("ao"))
            .await;
        assert!(matches!(refused, Err(StoreError::LeaseLost(_))));
    }
    let once = store
        .complete(again.job.id, &again.token, &done("ao"))
        .await
        .unwrap();
    // The same completion sent again (its answer was lost) is answered as
    // the first was and counted once; the stale token is still refused.
    let twice = store
        .complete(again.job.id, &again.token, &done("ao"))
        .await
        .unwrap();
    assert_eq!(
        (twice.id, twice.jobs_done, twice.done_work),
        (once.id, once.jobs_done, once.done_work)
    );
    let stale = store
        .complete(first.job.id, &first.token, &done("ao"))
        .await;
    assert!(matches!(stale, Err(StoreError::LeaseLost(_))), "{stale:?}");
    let (states, expiries) = store.queue_stats().await.unwrap();
    assert!(expiries >= 1);
    assert!(
        states
            .iter()
            .any(|(s, n)| *s == JobState::Completed && *n > 0)
    );
}

async fn failures_retry_then_kill_the_bake(store: &dyn Store) {
    let c = character(store).await;
    let b = store.create_bake(&bake(&c, &"3".repeat(64))).await.unwrap();
    let p = policy();
    // Drain other bakes' jobs out of the way by leasing only this bake's.
    let mut lease = store.lease("w", &p).await.unwrap().unwrap();
    while lease.job.bake_id != b.id {
        store
            .complete(lease.job.id, &lease.token, &done("ao"))
            .await
            .unwrap();
        lease = store.lease("w", &p).await.unwrap().unwrap();
    }
    let after = store
        .fail(lease.job.id, &lease.token, "flaky", true, &p)
        .await
        .unwrap();
    assert_eq!(after.state, BakeState::Running);
    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    let mut again = store.lease("w", &p).await.unwrap().unwrap();
    while again.job.id != lease.job.id {
        store
            .complete(again.job.id, &again.token, &done("ao"))
            .await
            .unwrap();
        again = store.lease("w", &p).await.unwrap().unwrap();
    }
    let end = store
        .fail(again.job.id, &again.token, "broken for good", true, &p)
        .await
        .unwrap();
    assert_eq!(end.state, BakeState::Failed, "out of attempts");
    // The job as the API and the workers' logs name it, its place in the
    // bake, its last worker and its error.
    assert_eq!(
        end.error.as_deref(),
        Some(
            format!(
                "job {} (sample, #{} of the bake) died after 2 attempts on w: broken for good",
                again.job.id, again.job.index
            )
            .as_str()
        )
    );
    let retried = store.control(b.id, Action::Retry).await.unwrap();
    assert_eq!(retried.state, BakeState::Queued);
}

/// A job leased again counts what it had reached (the bake's progress
/// never moves back) and shows the work it does again as such; a done
/// bake whose outputs the blob store lost is queued again with the jobs
/// that made them, its progress kept, and publishes its asset again.
async fn progress_only_moves_forward_and_lost_outputs_run_again(store: &dyn Store) {
    let c = character(store).await;
    let key = "9".repeat(64);
    // Above every other case's bakes: its jobs are leased first.
    let b = store
        .create_bake(&NewBake {
            priority: 100,
            ..bake(&c, &key)
        })
        .await
        .unwrap();
    let p = policy();
    let output = |name: &str, d: char| Completion {
        outputs: vec![OutputRef {
            name: name.into(),
            digest: d.to_string().repeat(64),
        }],
        timings: json!({}),
    };
    let a = store.lease("w", &p).await.unwrap().unwrap();
    assert_eq!((a.job.bake_id, a.job.index), (b.id, 0));
    store.heartbeat(a.job.id, &a.token, 1, &p).await.unwrap();
    // The attempt fails; what it reached still counts.
    let failed = store
        .fail(a.job.id, &a.token, "flaky", true, &p)
        .await
        .unwrap();
    assert_eq!((failed.running_work, failed.redo_work), (1, 0));
    assert_eq!(crate::state::progress_done(&failed), 1);
    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    let again = store.lease("w", &p).await.unwrap().unwrap();
    assert_eq!(again.job.id, a.job.id);
    let row = store.bake(b.id).await.unwrap().unwrap();
    assert_eq!((row.running_work, row.redo_work), (1, 1), "{row:?}");
    let beat = store
        .heartbeat(a.job.id, &again.token, 2, &p)
        .await
        .unwrap();
    assert_eq!((beat.bake.running_work, beat.bake.redo_work), (2, 0));
    let jobs = store.jobs(b.id).await.unwrap();
    assert_eq!((jobs[0].progress, jobs[0].reached), (2, 2));
    store
        .complete(a.job.id, &again.token, &output("ao", 'a'))
        .await
        .unwrap();
    let s2 = store.lease("w", &p).await.unwrap().unwrap();
    store
        .complete(s2.job.id, &s2.token, &output("ao", 'b'))
        .await
        .unwrap();
    let fit = store.lease("w", &p).await.unwrap().unwrap();
    let finished = store
        .complete(fit.job.id, &fit.token, &output("asset", 'f'))
        .await
        .unwrap();
    assert_eq!(finished.state, BakeState::Done);
    assert_eq!(finished.asset.as_deref(), Some("f".repeat(64).as_str()));
    // Nothing lost: a done bake is not queued again.
    assert!(matches!(
        store.retry(b.id, &[]).await,
        Err(StoreError::Conflict(_))
    ));
    // The first sample's output and the asset lost: both run again, the
    // second sample's is kept; the progress stays where it was and the
    // lost asset is not published meanwhile.
    let queued = store.retry(b.id, &[a.job.id, fit.job.id]).await.unwrap();
    assert_eq!(queued.state, BakeState::Queued);
    assert_eq!(
        (queued.done_work, queued.jobs_done, queued.running_work),
        (2, 1, 4)
    );
    assert_eq!(crate::state::progress_done(&queued), queued.total_work);
    assert_eq!(queued.asset, None);
    assert!(
        store
            .bakes_for_key(&key)
            .await
            .unwrap()
            .into_iter()
            .next()
            .unwrap()
            .state
            != BakeState::Done,
        "never a cache hit while lost"
    );
    let jobs = store.jobs(b.id).await.unwrap();
    let states: Vec<JobState> = jobs.iter().map(|j| j.state).collect();
    assert_eq!(
        states,
        [JobState::Available, JobState::Completed, JobState::Blocked]
    );
    let redo = store.lease("w", &p).await.unwrap().unwrap();
    assert_eq!(redo.job.id, a.job.id);
    assert_eq!(store.bake(b.id).await.unwrap().unwrap().redo_work, 2);
    store
        .complete(redo.job.id, &redo.token, &output("ao", 'a'))
        .await
        .unwrap();
    let refit = store.lease("w", &p).await.unwrap().unwrap();
    assert_eq!(refit.job.id, fit.job.id);
    let again = store
        .complete(refit.job.id, &refit.token, &output("asset", 'f'))
        .await
        .unwrap();
    assert_eq!(again.state, BakeState::Done);
    assert_eq!((again.done_work, again.jobs_done), (6, 3));
    assert_eq!(again.asset.as_deref(), Some("f".repeat(64).as_str()));
}

/// A failed bake's jobs that were still running are taken back by a
/// retry, with fresh attempts: their workers hear the lease is gone, and
/// none runs on with inputs a retry makes again or on its last attempt.
async fn a_retry_takes_back_the_jobs_a_failed_bake_still_ran(store: &dyn Store) {
    let c = character(store).await;
    let b = store
        .create_bake(&NewBake {
            priority: 100,
            ..bake(&c, &"8".repeat(64))
        })
        .await
        .unwrap();
    let p = policy();
    let one = store.lease("w1", &p).await.unwrap().unwrap();
    let two = store.lease("w2", &p).await.unwrap().unwrap();
    assert_eq!((one.job.bake_id, two.job.bake_id), (b.id, b.id));
    store
        .heartbeat(two.job.id, &two.token, 1, &p)
        .await
        .unwrap();
    let failed = store
        .fail(one.job.id, &one.token, "broken", false, &p)
        .await
        .unwrap();
    assert_eq!(failed.state, BakeState::Failed);
    let queued = store.control(b.id, Action::Retry).await.unwrap();
    assert_eq!(queued.state, BakeState::Queued);
    // What the running job had reached still counts.
    assert_eq!(crate::state::progress_done(&queued), 1);
    assert!(matches!(
        store.heartbeat(two.job.id, &two.token, 2, &p).await,
        Err(StoreError::LeaseLost(_))
    ));
    let jobs = store.jobs(b.id).await.unwrap();
    assert_eq!(
        (jobs[1].state, jobs[1].attempts),
        (JobState::Available, 0),
        "{jobs:?}"
    );
    // Leased again, by the first lease of the queued bake, with its
    // progress so far as work done again.
    let again = store.lease("w3", &p).await.unwrap().unwrap();
    let row = store.bake(b.id).await.unwrap().unwrap();
    assert_eq!(again.job.bake_id, b.id);
    assert_eq!(crate::state::progress_done(&row), 1, "{row:?}");
}

async fn cancel_pause_resume_retry(store: &dyn Store) {
    let c = character(store).await;
    let b = store.create_bake(&bake(&c, &"4".repeat(64))).await.unwrap();
    let paused = store.control(b.id, Action::Pause).await.unwrap();
    assert_eq!(paused.state, BakeState::Paused);
    assert!(matches!(
        store.control(b.id, Action::Pause).await,
        Err(StoreError::Conflict(_))
    ));
    let resumed = store.control(b.id, Action::Resume).await.unwrap();
    assert!(resumed.state.is_active());
    let cancelled = store.control(b.id, Action::Cancel).await.unwrap();
    assert_eq!(cancelled.state, BakeState::Cancelled);
    assert!(
        store
            .jobs(b.id)
            .await
            .unwrap()
            .iter()
            .all(|j| j.state == JobState::Cancelled)
    );
    assert!(
        store
            .bakes_for_key(&"4".repeat(64))
            .await
            .unwrap()
            .is_empty()
    );
    let p = store.set_priority(b.id, 7).await.unwrap();
    assert_eq!(p.priority, 7);
}

/// Many workers claiming at once each get a different job, and every job
/// is claimed once.
pub(crate) async fn concurrent_claims_are_exclusive(store: std::sync::Arc<dyn Store>) {
    let c = character(&*store).await;
    let job = |i: usize| NewJob {
        kind: "sample".into(),
        spec: json!({"kind": "sample", "i": i}),
        work: 1,
        deps: vec![],
    };
    let mut b = bake(&c, &"5".repeat(64));
    b.jobs = (0..40).map(job).collect();
    b.priority = 100;
    let created = store.create_bake(&b).await.unwrap();
    let tasks: Vec<_> = (0..8)
        .map(|w| {
            let store = store.clone();
            tokio::spawn(async move {
                let mut got = Vec::new();
                while let Some(l) = store.lease(&format!("w{w}"), &policy()).await.unwrap() {
                    got.push((l.job.bake_id, l.job.id));
                    store
                        .complete(l.job.id, &l.token, &done("ao"))
                        .await
                        .unwrap();
                }
                got
            })
        })
        .collect();
    let mut all = Vec::new();
    for t in tasks {
        all.extend(t.await.unwrap());
    }
    let mine: Vec<i64> = all
        .iter()
        .filter(|(b, _)| *b == created.id)
        .map(|(_, j)| *j)
        .collect();
    let mut unique = mine.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), mine.len(), "a job was claimed twice");
    assert_eq!(mine.len(), 40);
    let end = store.bake(created.id).await.unwrap().unwrap();
    assert_eq!(end.state, BakeState::Done);
}

/// Two servers on one store that shares events (`a` and `b`, each an
/// [`crate::state::AppState`] over its own connection): a bake event one
/// publishes reaches the other's listeners, and its own, once each.
pub(crate) async fn bake_events_reach_every_server(
    a: std::sync::Arc<dyn Store>,
    b: std::sync::Arc<dyn Store>,
) {
    use crate::state::{AppState, BakeEvent, ServerLimits};
    let dir = tempfile::tempdir().unwrap();
    let blobs = std::sync::Arc::new(crate::blobs::LocalBlobs::open(dir.path()).unwrap());
    let state = |store| AppState::new(store, blobs.clone(), policy(), ServerLimits::default());
    let (mut on_a, mut on_b) = (state(a.clone()), state(b));
    on_a.share_events().await.unwrap();
    on_b.share_events().await.unwrap();
    let (mut heard_a, mut heard_b) = (on_a.events.subscribe(), on_b.events.subscribe());
    let c = character(a.as_ref()).await;
    let row = a.create_bake(&bake(&c, "events")).await.unwrap();
    on_a.publish(&row);
    let expected = BakeEvent::of(&row);
    let within = std::time::Duration::from_secs(10);
    for heard in [&mut heard_a, &mut heard_b] {
        let event = tokio::time::timeout(within, heard.recv()).await;
        assert_eq!(event.unwrap().unwrap(), expected);
    }
    // Once each: nothing more arrives.
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    assert!(heard_a.try_recv().is_err() && heard_b.try_recv().is_err());
}
