//! A fleet on one machine: PostgreSQL, an S3 server, two API servers and
//! three workers, each in a network namespace of its own with its own
//! address, joined by a bridge the test makes (`netns::TestNet`). Links
//! are cut and processes killed mid-bake; the bake must end the same as
//! `aobake bake`'s.

use std::time::Duration;

use aobake_e2e::netns::TestNet;
use aobake_e2e::{ADMIN, Options, TestEnv, TestPostgres, TestS3, character};

use crate::util::{asset, local_bake, submit, upload};

#[test]
fn a_cluster_in_network_namespaces_finishes_a_bake_through_a_cut_link_and_kills() {
    let mut net = TestNet::new();
    let (db, s3) = (net.host("db"), net.host("s3"));
    let (host_a, host_b) = (net.host("api-a"), net.host("api-b"));
    let w = [net.host("w1"), net.host("w2"), net.host("w3")];
    let pg = TestPostgres::start_in(&db);
    let bucket = TestS3::start_in(&s3);
    let on = |host: &aobake_e2e::netns::Host| Options {
        database: Some(pg.url.clone()),
        blobs: Some(bucket.url.clone()),
        host: Some(host.clone()),
        job_rays: Some(0),
        lease_secs: 2.0,
        ..Options::default()
    };
    let mut a = TestEnv::start(on(&host_a));
    let mut b = TestEnv::start(on(&host_b));
    assert!(a.url.contains(&host_a.addr) && b.url.contains(&host_b.addr));
    // Workers 1 and 3 work through server A, worker 2 through B.
    let w1 = a.start_worker_in(&w[0], &[]);
    b.start_worker_in(&w[1], &[]);
    let w3 = a.start_worker_in(&w[2], &[]);

    let cesium = character("CesiumMan");
    let digest = upload(&a, &cesium);
    let (status, bake) = submit(&a, &digest, 48);
    assert_eq!(status, 202, "{bake}");
    let id = bake["id"].as_i64().unwrap();
    // Mid-bake, while workers 1 and 3 each hold a job: worker 1's link
    // is cut (it runs on, unheard), worker 3 is killed; then, once the
    // others have moved the bake on, server A dies too.
    a.wait_jobs_done(id, 3, Duration::from_secs(120));
    a.wait_for_bake(
        id,
        Duration::from_secs(60),
        "run jobs on workers 1 and 3 at once",
        |now| {
            let holds = |host: &aobake_e2e::netns::Host| {
                now["jobs"].as_array().unwrap().iter().any(|j| {
                    j["state"] == "running" && j["worker"].as_str() == Some(host.ns.as_str())
                })
            };
            holds(&w[0]) && holds(&w[2])
        },
    );
    net.cut(&w[0]);
    a.kill_worker(w3);
    let (_, now) = b
        .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap();
    let then = now["jobs_done"].as_i64().unwrap();
    b.wait_jobs_done(id, then + 2, Duration::from_secs(120));
    a.kill_server();

    let done = b.wait_bake(id, Duration::from_secs(300));
    assert_eq!(
        done["state"],
        "done",
        "{done}\n{}\n{}",
        a.worker_logs(),
        b.worker_logs()
    );
    assert_eq!(done["jobs_done"], done["jobs_total"], "{done}");
    // Every job completed once, the last ones on worker 2, the only one
    // left (worker 1 still runs, cut off: what it finishes is refused).
    let jobs = done["jobs"].as_array().unwrap();
    assert!(jobs.iter().all(|j| j["state"] == "completed"), "{done}");
    assert!(
        jobs.iter()
            .any(|j| j["worker"].as_str() == Some(w[1].ns.as_str())),
        "{done}"
    );
    // The jobs the cut-off and the killed workers held were leased again
    // once their leases ran out.
    let again: Vec<&serde_json::Value> = jobs
        .iter()
        .filter(|j| j["attempts"].as_i64() > Some(1))
        .collect();
    assert!(!again.is_empty(), "{done}");
    assert!(!a.worker_exited(w1), "the cut-off worker should still run");
    assert!(
        asset(&b, &done) == local_bake(b.dir.path(), &cesium, 48),
        "the cluster's asset differs from aobake bake's"
    );
}
