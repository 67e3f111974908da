//! Shared steps: uploads, submissions and local reference bakes.

use std::path::{Path, PathBuf};

use aobake_e2e::{ADMIN, TestEnv, binary};
use serde_json::{Value, json};

/// Small but real bake parameters (flags of `aobake bake` and `submit`).
pub(crate) const QUICK: &[&str] = &[
    "--method",
    "vertex-linear",
    "--samples",
    "32",
    "--eval-poses",
    "2",
    "--eval-fps",
    "10",
];

/// The same parameters as the API's `params` object, with `poses`.
pub(crate) fn quick_params(poses: usize) -> Value {
    json!({"samples": 32, "eval_poses": 2, "eval_fps": 10.0, "poses": poses})
}

/// Uploads a character under its file name; returns its digest.
pub(crate) fn upload(env: &TestEnv, path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let name = path.file_name().unwrap().to_str().unwrap();
    let (status, body, headers) = env.post_bytes(
        &format!("/v1/characters?name={name}"),
        ADMIN,
        "model/gltf-binary",
        &bytes,
    );
    assert!(status == 201 || status == 200, "{status} {body}");
    let digest = body["digest"].as_str().unwrap().to_owned();
    let location = headers.iter().find(|(k, _)| k == "location");
    assert_eq!(
        location.map(|(_, v)| v.as_str()),
        Some(format!("/v1/characters/{digest}").as_str())
    );
    digest
}

/// Submits a vertex-linear bake; returns the answer.
pub(crate) fn submit(env: &TestEnv, character: &str, poses: usize) -> (u16, Value) {
    env.request(
        "POST",
        "/v1/bakes",
        ADMIN,
        Some(json!({"character": character, "method": "vertex-linear", "params": quick_params(poses)})),
    )
    .unwrap()
}

/// `aobake bake` of the same request in this process's temp dir; returns
/// the asset bytes.
pub(crate) fn local_bake(dir: &Path, character: &Path, poses: usize) -> Vec<u8> {
    let poses = poses.to_string();
    let mut args: Vec<&str> = QUICK.to_vec();
    args.extend(["--poses", &poses]);
    aobake_bake(dir, character, &args, &format!("local-{poses}"))
}

/// `aobake bake CHARACTER ARGS…` into `dir/{name}.aob` (two tracing
/// threads, as the workers have, on the CPU tracer even where a GPU is);
/// returns the asset bytes.
pub(crate) fn aobake_bake(dir: &Path, character: &Path, args: &[&str], name: &str) -> Vec<u8> {
    aobake_bake_on(dir, character, args, name, "cpu").0
}

/// [`aobake_bake`] with `--tracer TRACER`; the asset bytes and what the
/// command printed on stderr.
pub(crate) fn aobake_bake_on(
    dir: &Path,
    character: &Path,
    args: &[&str],
    name: &str,
    tracer: &str,
) -> (Vec<u8>, String) {
    let out = dir.join(format!("{name}.aob"));
    let run = std::process::Command::new(binary())
        .arg("bake")
        .arg(character)
        .args(args)
        .arg("--out")
        .arg(&out)
        .arg("--report")
        .arg(dir.join(format!("{name}.json")))
        .args(["--tracer", tracer])
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "{stderr}");
    (std::fs::read(out).unwrap(), stderr)
}

/// A bake as `GET /v1/bakes/{id}` shows it.
pub(crate) fn bake_view(env: &TestEnv, id: i64) -> Value {
    env.request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
        .unwrap()
        .1
}

/// Waits (up to two minutes) for a running job of `kind` whose checkpoint
/// cursor has reached `cursor`; its id and cursor.
pub(crate) fn deep_running_job(env: &TestEnv, id: i64, kind: &str, cursor: i64) -> (i64, i64) {
    let started = std::time::Instant::now();
    loop {
        let now = bake_view(env, id);
        let deep = now["jobs"].as_array().unwrap().iter().find_map(|j| {
            let c = j["checkpoint"]["cursor"].as_i64().unwrap_or(0);
            (j["kind"] == kind && j["state"] == "running" && c >= cursor)
                .then(|| (j["id"].as_i64().unwrap(), c))
        });
        if let Some(d) = deep {
            return d;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(120),
            "{now}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The JSON output (`*.json`) of a finished job: how it ran.
pub(crate) fn job_info(env: &TestEnv, job: &Value) -> Value {
    let info = job["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["name"].as_str().unwrap().ends_with(".json"))
        .unwrap();
    env.request(
        "GET",
        &format!("/v1/blobs/{}", info["digest"].as_str().unwrap()),
        ADMIN,
        None,
    )
    .unwrap()
    .1
}

/// The asset bytes of a finished bake.
pub(crate) fn asset(env: &TestEnv, bake: &Value) -> Vec<u8> {
    let digest = bake["asset"]
        .as_str()
        .expect("a finished bake has an asset");
    let agent: ureq::Agent = ureq::Agent::config_builder().build().into();
    agent
        .get(format!("{}/v1/assets/{digest}", env.url))
        .header("authorization", format!("Bearer {ADMIN}"))
        .call()
        .unwrap()
        .body_mut()
        .with_config()
        .limit(1 << 30)
        .read_to_vec()
        .unwrap()
}

/// `aobake submit … --wait` running in the background, its stdout and
/// stderr in files, as a pipeline's step runs it.
pub(crate) struct Follower {
    pub(crate) child: std::process::Child,
    out: std::path::PathBuf,
    err: std::path::PathBuf,
}

impl Follower {
    /// Spawns `command` with its output in `dir/NAME.out` and `.err`.
    pub(crate) fn spawn(mut command: std::process::Command, dir: &Path, name: &str) -> Self {
        let (out, err) = (
            dir.join(format!("{name}.out")),
            dir.join(format!("{name}.err")),
        );
        let child = command
            .stdout(std::fs::File::create(&out).unwrap())
            .stderr(std::fs::File::create(&err).unwrap())
            .spawn()
            .unwrap();
        Self { child, out, err }
    }

    /// What it printed so far on stdout.
    pub(crate) fn stdout(&self) -> String {
        std::fs::read_to_string(&self.out).unwrap_or_default()
    }

    /// What it printed so far on stderr.
    pub(crate) fn stderr(&self) -> String {
        std::fs::read_to_string(&self.err).unwrap_or_default()
    }

    /// The bake id of its first line (`bake N: key K, STATE`), once it
    /// submitted; panics after 30 s.
    pub(crate) fn submitted(&self) -> i64 {
        let started = std::time::Instant::now();
        loop {
            let id = self
                .stdout()
                .strip_prefix("bake ")
                .and_then(|rest| rest.split_once(": key"))
                .and_then(|(id, _)| id.parse().ok());
            if let Some(id) = id {
                return id;
            }
            assert!(
                started.elapsed() < std::time::Duration::from_secs(30),
                "no submit: {}",
                self.stderr()
            );
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }
}

/// Runs `aobake worker` for `server` with `token` and `env` until it
/// exits, within a minute (else the test fails: it kept trying); its exit
/// status and log.
pub(crate) fn worker_until_it_exits(
    server: &str,
    token: &str,
    env: &[(&str, &std::ffi::OsStr)],
) -> (std::process::ExitStatus, String) {
    let mut child = std::process::Command::new(aobake_e2e::binary())
        .args(["worker", "--server", server, "--id", "refused"])
        .args(["--token", token])
        .envs(env.iter().copied())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let exit = loop {
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            panic!("a worker for {server} kept trying for a minute");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    (exit, stderr)
}

/// `aobake export ASSET --exr DIR` of `asset` (written beside it as
/// `served.aob`), which must succeed: the folder it wrote.
pub(crate) fn export_exr(env: &TestEnv, asset: &[u8]) -> PathBuf {
    let path = env.dir.path().join("served.aob");
    std::fs::write(&path, asset).unwrap();
    let exr_dir = env.dir.path().join("exr");
    let out = env.aobake(&[
        "export",
        path.to_str().unwrap(),
        "--exr",
        exr_dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exr_dir
}

/// The values of channel `name` of an OpenEXR layer as f32.
pub(crate) fn exr_channel(
    layer: &exr::prelude::Layer<exr::prelude::AnyChannels<exr::prelude::FlatSamples>>,
    name: &str,
) -> Vec<f32> {
    layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == name)
        .unwrap_or_else(|| panic!("no channel {name}"))
        .sample_data
        .values_as_f32()
        .collect()
}

/// Bake `id`'s server-sent events from the server at `url`, from its
/// current state (`start` runs once the stream is open) to `done`.
pub(crate) fn follow_events(url: &str, id: i64, start: impl FnOnce()) -> Vec<serde_json::Value> {
    use std::io::BufRead as _;
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .timeout_global(Some(std::time::Duration::from_secs(600)))
        .build()
        .into();
    let mut res = agent
        .get(format!("{url}/v1/bakes/{id}/events"))
        .header("authorization", format!("Bearer {ADMIN}"))
        .call()
        .unwrap();
    assert_eq!(
        res.headers()["content-type"].to_str().unwrap(),
        "text/event-stream"
    );
    start();
    let reader = std::io::BufReader::new(res.body_mut().as_reader());
    let mut events = Vec::new();
    for line in reader.lines() {
        let line = line.unwrap();
        if let Some(data) = line.strip_prefix("data: ") {
            let e: serde_json::Value = serde_json::from_str(data).unwrap();
            assert_eq!(e["id"], id);
            let done = e["state"] == "done";
            events.push(e);
            if done {
                break;
            }
        }
    }
    events
}
