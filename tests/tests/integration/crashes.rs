//! Crashes cost little and change nothing (DESIGN §8): workers SIGKILLed
//! at random moments, a worker that aborts right after a checkpoint, a
//! server SIGKILLed and restarted, a worker frozen past its lease.

use std::time::{Duration, Instant};

use aobake_e2e::{ADMIN, Options, TestEnv, TestPostgres, TestS3, character};
use rand::RngExt as _;
use serde_json::Value;

use crate::util::{Follower, QUICK, asset, follow_events, local_bake, submit, upload};

fn jobs(env: &TestEnv, id: i64) -> Vec<Value> {
    let (_, b) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    b["jobs"].as_array().cloned().unwrap_or_default()
}

/// Every job completed exactly once and the bake's counts add up.
fn assert_counted_once(bake: &Value, jobs: &[Value]) {
    assert_eq!(bake["state"], "done", "{bake}");
    assert_eq!(bake["jobs_done"], bake["jobs_total"]);
    assert_eq!(
        bake["done_work"], bake["total_work"],
        "no work counted twice"
    );
    let work: i64 = jobs.iter().map(|j| j["work"].as_i64().unwrap()).sum();
    assert_eq!(bake["total_work"].as_i64().unwrap(), work);
    assert!(jobs.iter().all(|j| j["state"] == "completed"));
}

#[test]
fn workers_killed_at_random_moments_change_no_byte() {
    let mut env = TestEnv::start(Options {
        lease_secs: 1.5,
        max_attempts: 30,
        job_rays: Some(0),
        ..Options::default()
    });
    let cm = character("CesiumMan");
    let digest = upload(&env, &cm);
    // 256 reference poses in batches of 4 and the held-out poses: over 50
    // jobs.
    let (status, b) = submit(&env, &digest, 256);
    assert_eq!(status, 202, "{b}");
    let id = b["id"].as_i64().unwrap();
    assert!(jobs(&env, id).len() >= 50);
    // Its events, followed throughout.
    let events = {
        let url = env.url.clone();
        std::thread::spawn(move || follow_events(&url, id, || {}))
    };
    // One worker aborts right after its first checkpoint; the others are
    // killed at random.
    env.start_worker(&[("AOBAKE_FAULT", "after_checkpoint")]);
    let mut live: Vec<usize> = vec![env.start_worker(&[]), env.start_worker(&[])];
    let mut rng = rand::rng();
    let mut kills = 0;
    let started = Instant::now();
    let mut seen = 0;
    loop {
        std::thread::sleep(Duration::from_millis(rng.random_range(150..600)));
        let (_, now) = env
            .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
            .unwrap();
        // Jobs leased again count what they had done: the bar never moves
        // back.
        let done = now["progress"]["done"].as_i64().unwrap();
        assert!(done >= seen, "progress went back from {seen} to {done}");
        seen = done;
        if now["state"] != "queued" && now["state"] != "running" {
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(240), "{now}");
        if kills < 8 {
            let victim = live.remove(rng.random_range(0..live.len()));
            env.kill_worker(victim);
            kills += 1;
            live.push(env.start_worker(&[]));
        }
    }
    let bake = env.wait_bake(id, Duration::from_secs(60));
    let jobs = jobs(&env, id);
    assert_counted_once(&bake, &jobs);
    assert!(kills >= 5, "only {kills} kills");
    // Nor do the events, however many jobs were leased again.
    let events = events.join().unwrap();
    let dones: Vec<i64> = events.iter().map(|e| e["done"].as_i64().unwrap()).collect();
    assert!(
        dones.windows(2).all(|w| w[0] <= w[1]),
        "the events' progress went back: {dones:?}"
    );
    let redone = events
        .iter()
        .filter(|e| e["redo"].as_i64() > Some(0))
        .count();
    eprintln!(
        "{} events, {redone} with work being done again",
        events.len()
    );
    let logs = env.worker_logs();
    assert!(logs.contains("fault injected after checkpoint"), "{logs}");
    // The aborted job resumed from its checkpoint: some sample job took
    // more than one attempt and kept a checkpoint cursor past 0.
    let resumed = jobs
        .iter()
        .filter(|j| j["kind"] == "sample" && j["attempts"].as_i64().unwrap() > 1)
        .filter(|j| j["checkpoint"]["cursor"].as_i64().unwrap_or(0) > 0)
        .count();
    assert!(resumed >= 1, "no sample job resumed from a checkpoint");
    let retried: i64 = jobs
        .iter()
        .map(|j| j["attempts"].as_i64().unwrap() - 1)
        .sum();
    eprintln!(
        "{} jobs, {kills} kills, {retried} extra attempts, {resumed} resumed from checkpoints",
        jobs.len()
    );
    assert!(
        asset(&env, &bake) == local_bake(env.dir.path(), &cm, 256),
        "the disturbed bake's asset differs from an undisturbed one"
    );
}

/// CesiumMan's bake (64 poses) with two workers, once four of its jobs
/// are done: a bake to disturb mid-way. Returns the character and the
/// bake's id.
fn cesium_man_under_way(env: &mut TestEnv) -> (std::path::PathBuf, i64) {
    let cm = character("CesiumMan");
    let digest = upload(env, &cm);
    let (_, b) = submit(env, &digest, 64);
    let id = b["id"].as_i64().unwrap();
    env.start_worker(&[]);
    env.start_worker(&[]);
    env.wait_jobs_done(id, 4, Duration::from_secs(120));
    (cm, id)
}

#[test]
fn a_server_killed_mid_bake_restarts_and_finishes_the_same() {
    let mut env = TestEnv::start(Options {
        lease_secs: 2.0,
        ..Options::default()
    });
    let (cm, id) = cesium_man_under_way(&mut env);
    let url = env.url.clone();
    env.kill_server();
    std::thread::sleep(Duration::from_millis(500));
    // Same port, so the workers find it again.
    env.start_server_on(url.trim_start_matches("http://"));
    let bake = env.wait_bake(id, Duration::from_secs(180));
    assert_counted_once(&bake, &jobs(&env, id));
    assert!(asset(&env, &bake) == local_bake(env.dir.path(), &cm, 64));
}

/// A server away for several seconds (a restart) costs the workers no
/// work: what they finish meanwhile is handed in when it is back, within
/// the lease, so no job runs twice. A `submit --wait` following the bake
/// waits for the server too and ends with the bake.
#[test]
fn work_finished_while_the_server_restarts_is_handed_in_when_it_is_back() {
    let mut env = TestEnv::start(Options {
        lease_secs: 120.0,
        ..Options::default()
    });
    // A longer bake than the other drills' (192 poses), so that much of it
    // is left when the server goes.
    let poses = 192;
    let cm = character("CesiumMan");
    let digest = upload(&env, &cm);
    let (_, b) = submit(&env, &digest, poses);
    let id = b["id"].as_i64().unwrap();
    env.start_worker(&[]);
    env.start_worker(&[]);
    env.wait_jobs_done(id, 1, Duration::from_secs(120));
    let url = env.url.clone();
    // The same request joins the bake under way and follows it.
    let poses_arg = poses.to_string();
    let mut args = vec![
        "submit",
        cm.to_str().unwrap(),
        "--poses",
        &poses_arg,
        "--wait",
    ];
    args.extend(QUICK);
    let mut follower = Follower::spawn(env.aobake_command(&args), env.dir.path(), "follow");
    assert_eq!(follower.submitted(), id, "the same bake");
    let before = jobs(&env, id);
    env.kill_server();
    // Longer than a job takes here, so that jobs finish while it is away.
    std::thread::sleep(Duration::from_secs(6));
    env.start_server_on(url.trim_start_matches("http://"));
    let bake = env.wait_bake(id, Duration::from_secs(150));
    let after = jobs(&env, id);
    assert_counted_once(&bake, &after);
    assert!(
        before.iter().any(|j| j["state"] == "running"),
        "jobs were running at the kill: {before:?}"
    );
    // Work was handed in (or fetched) through the outage, not dropped.
    let logs = env.worker_logs();
    assert!(logs.contains("retrying (for up to"), "{logs}");
    // A job's failing heartbeats are said once (then every 30 s), not a
    // line a second.
    for job in &before {
        let said = format!("job {}: heartbeat failed", job["id"]);
        assert!(logs.matches(&said).count() <= 1, "{logs}");
    }
    let twice: Vec<&Value> = after.iter().filter(|j| j["attempts"] != 1).collect();
    assert!(twice.is_empty(), "jobs run again: {twice:?}");
    // Each worker line says when it was written (UTC), so a log tells when
    // the retries began and the jobs ended.
    let lines: Vec<&str> = logs
        .lines()
        .filter(|l| l.contains(" done in ") || l.contains("retrying"))
        .collect();
    assert!(lines.len() >= 2, "{logs}");
    for line in lines {
        let stamp = line.split(' ').next().unwrap();
        assert!(humantime::parse_rfc3339(stamp).is_ok(), "{line}");
    }
    let followed = follower.child.wait().unwrap();
    let (stdout, stderr) = (follower.stdout(), follower.stderr());
    assert!(
        followed.success()
            && stdout.contains(&format!("bake {id} done"))
            && stderr.contains("asking again")
            && stderr.contains("the server answers again"),
        "{stdout}\n{stderr}"
    );
    assert!(asset(&env, &bake) == local_bake(env.dir.path(), &cm, poses));
}

/// Ctrl-C during `submit --wait` stops the following, not the bake: it
/// says so, with the commands that follow or cancel it, and exits 130.
#[test]
fn ctrl_c_during_submit_wait_leaves_the_bake_running_and_says_how_to_follow_it() {
    let env = TestEnv::start(Options::default());
    let rig = character("RiggedSimple");
    let mut args = vec!["submit", rig.to_str().unwrap(), "--poses", "8", "--wait"];
    args.extend(QUICK);
    let mut follower = Follower::spawn(env.aobake_command(&args), env.dir.path(), "interrupted");
    // No worker: the bake waits in the queue while it is followed.
    let id = follower.submitted();
    // The handler is set as the following starts, right after that line.
    std::thread::sleep(Duration::from_secs(1));
    let pid = nix::unistd::Pid::from_raw(follower.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let status = follower.child.wait().unwrap();
    let stderr = follower.stderr();
    assert_eq!(status.code(), Some(130), "{stderr}");
    for said in [
        format!("stopped following bake {id}; it goes on on the server"),
        format!("follow it: aobake status {id}"),
        format!("stop it:   aobake cancel {id}"),
    ] {
        assert!(stderr.contains(&said), "{said:?} in {stderr}");
    }
    let (_, bake) = env
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    assert_eq!(bake["state"], "queued", "{bake}");
}

/// `submit --wait` that took the server's address from the data folder
/// (as on one machine) follows a server started again on another port:
/// port 0 picks a new one at each start, and `DIR/server.url` says which.
#[test]
fn submit_wait_follows_a_server_restarted_on_another_port() {
    let mut env = TestEnv::start(Options::default());
    let rig = character("RiggedSimple");
    let data = env.data();
    let mut args = vec!["submit", rig.to_str().unwrap(), "--poses", "8", "--wait"];
    args.extend(QUICK);
    args.extend(["--data", data.to_str().unwrap()]);
    let mut command = env.aobake_command(&args);
    command.env_remove("AOBAKE_SERVER");
    let mut follower = Follower::spawn(command, env.dir.path(), "moved");
    // No worker yet: the bake waits while the server moves.
    follower.submitted();
    let before = env.url.clone();
    env.kill_server();
    env.start_server();
    assert_ne!(env.url, before, "port 0 picked the same port again");
    env.start_worker(&[]);
    let followed = follower.child.wait().unwrap();
    let (stdout, stderr) = (follower.stdout(), follower.stderr());
    assert!(
        followed.success()
            && stdout.contains(" done: asset ")
            && stderr.contains(&format!("following it at {}", env.url)),
        "{stdout}\n{stderr}"
    );
}

/// A fleet without a load balancer: workers given every server's address
/// go on with the next when the one they ask dies mid-bake, so its jobs
/// keep their leases (no server reaps them, none runs twice) and the bake
/// ends as `aobake bake`'s.
#[test]
fn workers_go_on_with_another_server_when_theirs_dies() {
    let pg = TestPostgres::start();
    let shared = tempfile::tempdir().unwrap();
    let on = Options {
        database: Some(pg.url.clone()),
        blobs: Some(shared.path().to_str().unwrap().to_owned()),
        lease_secs: 3.0,
        ..Options::default()
    };
    let mut a = TestEnv::start(on.clone());
    let b = TestEnv::start(on);
    let servers = format!("{},{}", a.url, b.url);
    a.start_worker_for(&servers);
    a.start_worker_for(&servers);
    let cm = character("CesiumMan");
    let digest = upload(&a, &cm);
    let poses = 48;
    let (_, bake) = submit(&a, &digest, poses);
    let id = bake["id"].as_i64().unwrap();
    a.wait_jobs_done(id, 2, Duration::from_secs(120));
    a.kill_server();
    let done = b.wait_bake(id, Duration::from_secs(240));
    let logs = a.worker_logs();
    assert_eq!(done["state"], "done", "{done}\n{logs}");
    assert!(
        logs.contains(&format!(
            "{} cannot be reached: going on with {}",
            a.url, b.url
        )),
        "{logs}"
    );
    let jobs: Vec<Value> = jobs(&b, id);
    let twice: Vec<&Value> = jobs.iter().filter(|j| j["attempts"] != 1).collect();
    assert!(twice.is_empty(), "jobs run again: {twice:?}\n{logs}");
    assert!(asset(&b, &done) == local_bake(b.dir.path(), &cm, poses));
}

#[test]
fn a_postgres_restart_mid_bake_answers_503_then_loses_nothing() {
    let pg = TestPostgres::start();
    let mut env = TestEnv::start(Options {
        database: Some(pg.url.clone()),
        lease_secs: 2.0,
        ..Options::default()
    });
    let (cm, id) = cesium_man_under_way(&mut env);
    pg.stop();
    // While it is down a request is told to come back, not failed.
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let res = agent
        .get(format!("{}/v1/bakes/{id}", env.url))
        .header("authorization", format!("Bearer {ADMIN}"))
        .call()
        .unwrap();
    assert_eq!(res.status().as_u16(), 503);
    let retry: u64 = res.headers()["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!((1..=30).contains(&retry), "{retry}");
    // The readiness probe says the same, so a load balancer looks elsewhere.
    let mut probe = agent.get(format!("{}/readyz", env.url)).call().unwrap();
    assert_eq!(probe.status().as_u16(), 503);
    let text = probe.body_mut().read_to_string().unwrap();
    assert!(text.contains("the database is not answering"), "{text}");
    std::thread::sleep(Duration::from_secs(3));
    pg.start_again();
    // The workers went on waiting; the bake finishes, every job counted
    // once, the same bytes as `aobake bake`. The outage outlasted the
    // leases (2 s), but no job lost its lease: the server reaps none
    // until the workers could renew theirs.
    let bake = env.wait_bake(id, Duration::from_secs(180));
    let after = jobs(&env, id);
    assert_counted_once(&bake, &after);
    let twice: Vec<&Value> = after.iter().filter(|j| j["attempts"] != 1).collect();
    assert!(twice.is_empty(), "jobs run again: {twice:?}");
    // The workers said why they waited.
    let logs = env.worker_logs();
    assert!(
        logs.contains("answered 503 (the database is not answering"),
        "{logs}"
    );
    // And when it was over, as the server's log does.
    assert!(logs.contains(" answers again after "), "{logs}");
    // Each says how long the whole outage was, as it saw it: at least
    // the 3 s it was down after this test's own 503s.
    let seconds = |text: &str, said: &str| -> Vec<u64> {
        text.match_indices(said)
            .filter_map(|(i, _)| {
                let rest = &text[i + said.len()..];
                rest[..rest.find(' ')?].parse().ok()
            })
            .collect()
    };
    let log = env.server_log();
    let server = seconds(&log, "the database answers again, after ");
    assert!(server.iter().any(|&s| s >= 3), "{server:?}\n{log}");
    let clients = seconds(&logs, " answers again after ");
    assert!(clients.iter().any(|&s| s >= 3), "{clients:?}\n{logs}");
    assert!(asset(&env, &bake) == local_bake(env.dir.path(), &cm, 64));
}

/// An S3 outage answers 503 with Retry-After, names the store, and its
/// end is logged.
#[test]
fn an_s3_outage_answers_503_with_retry_after() {
    let mut s3 = TestS3::start();
    let env = TestEnv::start(Options {
        blobs: Some(s3.url.clone()),
        ..Options::default()
    });
    let digest = upload(&env, &character("RiggedSimple"));
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let get = || {
        agent
            .get(format!("{}/v1/assets/{digest}", env.url))
            .header("authorization", format!("Bearer {ADMIN}"))
            .call()
            .unwrap()
    };
    assert_eq!(get().status().as_u16(), 200);
    s3.stop();
    // Reads and uploads while the store is down are told to come back,
    // within the store client's bounded retries, not failed with 500.
    let started = Instant::now();
    let read = get();
    let fox = std::fs::read(character("Fox")).unwrap();
    let (status, problem, headers) = env.post_bytes(
        "/v1/characters?name=Fox.glb",
        ADMIN,
        "model/gltf-binary",
        &fox,
    );
    assert!(
        started.elapsed() < Duration::from_secs(40),
        "{:?}",
        started.elapsed()
    );
    assert_eq!(read.status().as_u16(), 503);
    assert_eq!(read.headers()["retry-after"].to_str().unwrap(), "5");
    assert_eq!(
        (status, problem["code"].as_str()),
        (503, Some("unavailable")),
        "{problem}"
    );
    // It names what is down, so an operator looks at the store, not at
    // the database.
    let detail = problem["detail"].as_str().unwrap_or_default();
    assert!(
        detail.starts_with("the blob store is not answering"),
        "{detail}"
    );
    assert!(
        headers.iter().any(|(k, v)| k == "retry-after" && v == "5"),
        "{headers:?}"
    );
    // The readiness probe says the same, so a load balancer looks elsewhere.
    let mut probe = agent.get(format!("{}/readyz", env.url)).call().unwrap();
    assert_eq!(probe.status().as_u16(), 503);
    let text = probe.body_mut().read_to_string().unwrap();
    assert!(text.contains("the blob store is not answering"), "{text}");
    // Back without its bucket (an S3 server restarted without its data):
    // still an outage, which says what is missing, and not "answers
    // again" while nothing can be stored.
    s3.start_again_without_bucket();
    let (status, problem, _) = env.post_bytes(
        "/v1/characters?name=Fox.glb",
        ADMIN,
        "model/gltf-binary",
        &fox,
    );
    assert_eq!(status, 503, "{problem}");
    let detail = problem["detail"].as_str().unwrap_or_default();
    assert!(detail.contains("its bucket does not exist"), "{detail}");
    let mut probe = agent.get(format!("{}/readyz", env.url)).call().unwrap();
    assert_eq!(probe.status().as_u16(), 503);
    let text = probe.body_mut().read_to_string().unwrap();
    assert!(text.contains("its bucket does not exist"), "{text}");
    assert!(
        !env.server_log().contains("the blob store answers again"),
        "{}",
        env.server_log()
    );
    // The bucket made again (empty, as moto keeps nothing): ready again,
    // and the log says when the outage ended, not only each request it
    // failed.
    s3.make_bucket();
    let started = Instant::now();
    while agent
        .get(format!("{}/readyz", env.url))
        .call()
        .unwrap()
        .status()
        != 200
    {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "not ready again"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let log = env.server_log();
    assert!(log.contains("not answering (503)"), "{log}");
    assert!(
        log.contains("the blob store answers again, after "),
        "{log}"
    );
}

/// A server given a bucket that is not there refuses to start and names
/// it (a HEAD on an object answers a plain 404 there, so it would have
/// said ready and failed every upload with 500), and shows no secret
/// given in the URL.
#[test]
fn serve_refuses_a_bucket_that_is_not_there() {
    let s3 = TestS3::start();
    let dir = tempfile::tempdir().unwrap();
    let url = format!(
        "{}&aws_secret_access_key=SECRETXYZ",
        s3.url.replace("aobake-test", "no-such-bucket")
    );
    let out = serve_once(&["--blobs", &url], dir.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("cannot be used") && stderr.contains("no-such-bucket"),
        "{stderr}"
    );
    assert!(!stderr.contains("SECRETXYZ"), "{stderr}");
}

#[test]
fn a_worker_frozen_past_its_lease_has_its_completion_refused() {
    let mut env = TestEnv::start(Options {
        lease_secs: 1.0,
        ..Options::default()
    });
    let cm = character("CesiumMan");
    let digest = upload(&env, &cm);
    let (_, b) = submit(&env, &digest, 16);
    let id = b["id"].as_i64().unwrap();
    let frozen = env.start_worker(&[]);
    // Wait until it holds a job, then SIGSTOP it past its lease.
    let started = Instant::now();
    loop {
        if jobs(&env, id).iter().any(|j| j["state"] == "running") {
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(20));
    }
    env.signal_worker(frozen, nix::sys::signal::Signal::SIGSTOP);
    std::thread::sleep(Duration::from_millis(2500));
    // Another worker takes the expired job over and finishes the bake.
    env.start_worker(&[]);
    let bake = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(bake["state"], "done");
    env.signal_worker(frozen, nix::sys::signal::Signal::SIGCONT);
    // Resumed, the frozen worker's checkpoint, heartbeat or completion
    // meets 409: it notes the lost lease and goes on leasing.
    let started = Instant::now();
    loop {
        let log = std::fs::read_to_string(env.dir.path().join("worker-0.log")).unwrap();
        if log.contains("409")
            || log.contains("lease was lost")
            || log.contains("completion refused")
        {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the frozen worker's stale lease was not refused: {log}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_counted_once(&bake, &jobs(&env, id));
    let (_, metrics) = env.request("GET", "/metrics", ADMIN, None).unwrap();
    assert!(
        !metrics
            .as_str()
            .unwrap()
            .contains("aobake_lease_expiries_total 0\n")
    );
}

/// A job that dies (its worker killed, one attempt allowed) fails its
/// bake with a reason that names the job as the API and the workers' logs
/// do, its place in the bake, its worker and its cause; a worker that was
/// running another of its jobs stops saying the bake failed, not that it
/// was cancelled.
#[test]
fn a_dead_job_fails_its_bake_with_a_reason_that_names_it() {
    let mut env = TestEnv::start(Options {
        lease_secs: 1.5,
        max_attempts: 1,
        ..Options::default()
    });
    let digest = upload(&env, &character("CesiumMan"));
    let (_, b) = submit(&env, &digest, 48);
    let id = b["id"].as_i64().unwrap();
    let victim = env.start_worker(&[]);
    // A slow worker (300 ms a traced pose) is still under way when the
    // bake fails.
    env.start_worker(&[("AOBAKE_FAULT", "slow")]);
    env.wait_for_bake(
        id,
        Duration::from_secs(60),
        "run jobs on w0 and w1",
        |now| {
            let holds = |w: &str| {
                now["jobs"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|j| j["state"] == "running" && j["worker"] == w)
            };
            holds("w0") && holds("w1")
        },
    );
    env.kill_worker(victim);
    let end = env.wait_bake(id, Duration::from_secs(120));
    assert_eq!(end["state"], "failed", "{end}");
    let jobs = end["jobs"].as_array().unwrap();
    let dead = jobs.iter().find(|j| j["state"] == "dead").unwrap();
    assert_eq!(
        end["error"],
        format!(
            "job {} ({}, #{} of the bake) died after 1 attempt on w0: lease expired",
            dead["id"],
            dead["kind"].as_str().unwrap(),
            dead["index"]
        ),
        "{end}"
    );
    let said = "stopped (the bake failed (another of its jobs died))";
    let started = std::time::Instant::now();
    while !env.worker_logs().contains(said) {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{}",
            env.worker_logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(!env.worker_logs().contains("the bake was cancelled"));
}

/// A server whose database cannot be used says why: a port that refuses
/// (not only that a pool timed out), and another scheme than PostgreSQL's
/// as a wrong command line.
#[test]
fn serve_says_why_it_cannot_use_its_database() {
    let dir = tempfile::tempdir().unwrap();
    let serve = |database: &str| serve_once(&["--database", database], dir.path());
    let refused = serve("postgres://aobake@127.0.0.1:1/aobake");
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    assert!(stderr.contains("Connection refused"), "{stderr}");
    assert_eq!(
        stderr.matches("Connection refused").count(),
        1,
        "said once: {stderr}"
    );
    let mysql = serve("mysql://x");
    let stderr = String::from_utf8_lossy(&mysql.stderr);
    assert_eq!(mysql.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--database takes a PostgreSQL URL"),
        "{stderr}"
    );
}

/// `aobake serve ARGS` on `data` (any port, no local worker), run to its
/// end: for a start that must be refused.
fn serve_once(args: &[&str], data: &std::path::Path) -> std::process::Output {
    std::process::Command::new(aobake_e2e::binary())
        .args(["serve", "--listen", "127.0.0.1:0", "--workers", "0"])
        .args(args)
        .arg("--data")
        .arg(data)
        .output()
        .unwrap()
}

/// A proxy in front of a server that drops the first successful answer
/// to requests starting `what` (`POST /v1/jobs/leases`): the server
/// committed what was asked, the worker never heard of it. Every request
/// goes through it on a connection of its own, its body read by its
/// `Content-Length` (the client sends no chunked body).
struct AnswerDropper {
    url: String,
    dropped: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl AnswerDropper {
    fn start(server: &str, what: &'static str) -> Self {
        use std::io::{BufRead as _, BufReader, Read as _, Write as _};
        use std::sync::atomic::Ordering;
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let upstream = server.trim_start_matches("http://").to_owned();
        let dropped = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = dropped.clone();
        std::thread::spawn(move || {
            for client in listener.incoming().flatten() {
                let (upstream, flag) = (upstream.clone(), flag.clone());
                std::thread::spawn(move || -> std::io::Result<()> {
                    let mut reader = BufReader::new(client.try_clone()?);
                    let mut client = client;
                    // One request: its head, with `Connection: close`
                    // upstream, and its body by its length.
                    let mut head = Vec::new();
                    let mut length = 0usize;
                    let mut first = String::new();
                    loop {
                        let mut line = String::new();
                        if reader.read_line(&mut line)? == 0 {
                            return Ok(());
                        }
                        if first.is_empty() {
                            first = line.clone();
                        }
                        let lower = line.to_ascii_lowercase();
                        if let Some(v) = lower.strip_prefix("content-length:") {
                            length = v.trim().parse().unwrap_or(0);
                        }
                        if lower.starts_with("connection:") {
                            continue;
                        }
                        if line == "\r\n" {
                            head.extend_from_slice(b"Connection: close\r\n\r\n");
                            break;
                        }
                        head.extend_from_slice(line.as_bytes());
                    }
                    let mut body = vec![0; length];
                    reader.read_exact(&mut body)?;
                    let mut up = std::net::TcpStream::connect(&upstream)?;
                    up.write_all(&head)?;
                    up.write_all(&body)?;
                    let mut answer = Vec::new();
                    up.read_to_end(&mut answer)?;
                    let done = first.starts_with(what) && answer.starts_with(b"HTTP/1.1 200");
                    // The first such answer is dropped: committed by the
                    // server, never heard of.
                    let drop_it = done && !flag.swap(true, Ordering::SeqCst);
                    if !drop_it {
                        client.write_all(&answer)?;
                    }
                    Ok(())
                });
            }
        });
        Self { url, dropped }
    }
}

/// A RiggedSimple bake by one worker behind an [`AnswerDropper`] of
/// `what`, with a 10 s lease (a job run twice shows as attempts 2 once it
/// expires; a busy machine's slow heartbeat does not): the server, the
/// finished bake and the worker's log, once the bake finished done with
/// one answer dropped and every job attempted once.
fn bake_dropping_an_answer(what: &'static str) -> (TestEnv, Value, String) {
    let mut env = TestEnv::start(Options {
        lease_secs: 10.0,
        ..Options::default()
    });
    let proxy = AnswerDropper::start(&env.url, what);
    let digest = upload(&env, &character("RiggedSimple"));
    let (_, b) = submit(&env, &digest, 8);
    let id = b["id"].as_i64().unwrap();
    env.start_worker_for(&proxy.url);
    let done = env.wait_bake(id, Duration::from_secs(120));
    let logs = env.worker_logs();
    assert_eq!(done["state"], "done", "{done}\n{logs}");
    assert!(
        proxy.dropped.load(std::sync::atomic::Ordering::SeqCst),
        "no answer to {what} was dropped"
    );
    let twice: Vec<&Value> = done["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|j| j["attempts"] != 1)
        .collect();
    assert!(twice.is_empty(), "jobs run again: {twice:?}\n{logs}");
    (env, done, logs)
}

/// A lease whose answer is lost (the server committed it; the worker's
/// connection closed before the answer) is not run twice: the worker
/// asks again with the same request nonce and gets the same jobs, same
/// attempts, so every job of the bake is attempted once and the asset is
/// `aobake bake`'s.
#[test]
fn a_lease_whose_answer_was_lost_is_answered_again_not_run_twice() {
    let (env, done, logs) = bake_dropping_an_answer("POST /v1/jobs/leases");
    assert!(logs.contains("cannot lease"), "{logs}");
    let rigged = character("RiggedSimple");
    assert!(asset(&env, &done) == local_bake(env.dir.path(), &rigged, 8));
}

/// A completion whose answer is lost (the server recorded it; the
/// worker's connection closed before the answer) is sent again and
/// answered as the first was: the job is counted once, never refused,
/// so every job of the bake is attempted once.
#[test]
fn a_completion_whose_answer_was_lost_is_answered_again_and_counted_once() {
    let (_env, done, logs) = bake_dropping_an_answer("POST /v1/jobs/completions");
    assert!(!logs.contains("completion refused"), "{logs}");
    assert_eq!(done["jobs_done"], done["jobs_total"], "{done}");
}

/// A bake in flight whose finished jobs' outputs vanish from the blob
/// store (an emptied bucket, an expired object): the first job that reads
/// one fails the bake at once, without burning attempts, saying how to go
/// on; `aobake retry` then runs the lost jobs again, and the bake ends
/// with the same bytes as `aobake bake`.
#[test]
fn a_bake_whose_inputs_vanish_mid_flight_fails_at_once_and_retry_finishes_it() {
    // Small jobs: most of the samples are still to run when four are done.
    let mut env = TestEnv::start(Options {
        job_rays: Some(0),
        ..Options::default()
    });
    let (cm, id) = cesium_man_under_way(&mut env);
    // What the jobs finished so far stored, deleted behind the server's
    // back.
    let mut deleted = 0;
    for j in jobs(&env, id).iter().filter(|j| j["state"] == "completed") {
        for o in j["outputs"].as_array().unwrap() {
            let d = o["digest"].as_str().unwrap();
            let file = env.data().join("blobs").join(&d[..2]).join(d);
            deleted += usize::from(std::fs::remove_file(file).is_ok());
        }
    }
    assert!(deleted > 0);
    let failed = env.wait_bake(id, Duration::from_secs(240));
    assert_eq!(failed["state"], "failed", "{failed}");
    let error = failed["error"].as_str().unwrap_or_default();
    assert!(
        error.contains(&format!(
            "is gone from the blob store: `aobake retry {id}` runs the job that made it again"
        )) && error.contains("after 1 attempt"),
        "{error}"
    );
    let out = env.aobake(&["retry", &id.to_string()]);
    assert!(out.status.success(), "{out:?}");
    let done = env.wait_bake(id, Duration::from_secs(240));
    assert_eq!(done["state"], "done", "{done}");
    assert!(asset(&env, &done) == local_bake(env.dir.path(), &cm, 64));
}
