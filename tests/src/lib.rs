//! # aobake-e2e
//!
//! End-to-end tests of the service with real processes (STYLE.md,
//! "Tests"). [`TestEnv`] owns a temporary data directory, starts the real
//! `aobake serve` on a port the OS picks (reading the URL it writes), starts
//! and kills real `aobake worker` processes, and kills everything on drop.
//!
//! The tests live in `tests/`; they need the `aobake` binary, which
//! `cargo test --workspace` builds (or `cargo build --bin aobake`).

pub mod hostile;
pub mod netns;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// The admin token every test server starts with.
pub const ADMIN: &str = "e2e-admin-token-0123456789abcdef";

/// The `aobake` binary beside this test's executable (`target/<profile>`),
/// or `AOBAKE_BIN`.
pub fn binary() -> PathBuf {
    if let Ok(p) = std::env::var("AOBAKE_BIN") {
        return p.into();
    }
    let exe = std::env::current_exe().expect("test executable");
    let dir = exe.parent().and_then(Path::parent).expect("target dir");
    let bin = dir.join("aobake");
    assert!(
        bin.is_file(),
        "{} is missing: run `cargo build --bin aobake` (cargo test --workspace builds it)",
        bin.display()
    );
    bin
}

/// The repository's root.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("repo")
        .to_owned()
}

/// A bundled character.
pub fn character(name: &str) -> PathBuf {
    repo().join(format!("tests/data/characters/{name}/{name}.glb"))
}

/// How the test server runs.
#[derive(Debug, Clone)]
pub struct Options {
    /// Lease length.
    pub lease_secs: f64,
    /// Leases per job.
    pub max_attempts: u32,
    /// Largest body.
    pub max_body_bytes: u64,
    /// Requests per second per token.
    pub rate: u32,
    /// Seconds a client has to send its request headers.
    pub header_timeout_secs: f64,
    /// `--job-rays`, when not the server's default (0: 4 poses a job,
    /// for tests that need many small jobs).
    pub job_rays: Option<u64>,
    /// `--max-bake-input-bytes`, when not the server's default.
    pub max_bake_input_bytes: Option<u64>,
    /// `--blobs`, when not the data directory (an S3 bucket: [`TestS3`]).
    pub blobs: Option<String>,
    /// `--database`, when not SQLite in the data directory (PostgreSQL:
    /// [`TestPostgres`]).
    pub database: Option<String>,
    /// The host of a [`netns::TestNet`] the server runs on (on its
    /// address, port 8080), when not this one.
    pub host: Option<netns::Host>,
    /// `--tls-cert` and `--tls-key`: https on the server's port
    /// ([`TestEnv::public_url`]); [`TestEnv::url`] is then its plain
    /// listener for this machine.
    pub tls: Option<(PathBuf, PathBuf)>,
    /// Local worker processes the server starts (`--workers`).
    pub local_workers: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            lease_secs: 3.0,
            max_attempts: 5,
            max_body_bytes: 64 << 20,
            rate: 10_000,
            header_timeout_secs: 10.0,
            job_rays: None,
            max_bake_input_bytes: None,
            blobs: None,
            database: None,
            host: None,
            tls: None,
            local_workers: 0,
        }
    }
}

/// A running server, its workers and its data directory.
#[derive(Debug)]
pub struct TestEnv {
    /// The data directory.
    pub dir: tempfile::TempDir,
    /// The server's URL.
    pub url: String,
    server: Option<Child>,
    workers: Vec<Option<Child>>,
    options: Options,
}

impl TestEnv {
    /// Starts a server with no local workers.
    pub fn start(options: Options) -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut env = Self {
            dir,
            url: String::new(),
            server: None,
            workers: Vec::new(),
            options,
        };
        env.start_server();
        env
    }

    /// The server process's id, while it runs.
    pub fn server_pid(&self) -> Option<u32> {
        self.server.as_ref().map(Child::id)
    }

    /// The data directory's path.
    pub fn data(&self) -> PathBuf {
        self.dir.path().join("data")
    }

    /// (Re)starts the server on the same data directory, on a free port
    /// (or its host's address, port 8080).
    pub fn start_server(&mut self) {
        let listen = match &self.options.host {
            Some(h) => format!("{}:8080", h.addr),
            None => "127.0.0.1:0".to_owned(),
        };
        self.start_server_on(&listen);
    }

    /// (Re)starts the server on the same data directory and `listen`.
    pub fn start_server_on(&mut self, listen: &str) {
        let url_file = self.data().join("server.url");
        let _ = std::fs::remove_file(&url_file);
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.path().join("server.log"))
            .expect("log");
        let o = &self.options;
        let mut command = match &o.host {
            Some(h) => h.command(binary()),
            None => Command::new(binary()),
        };
        let out = std::fs::File::create(self.dir.path().join("server.out")).expect("out");
        let child = command
            .args(["serve", "--listen", listen])
            .args(["--workers", &o.local_workers.to_string()])
            .arg("--data")
            .arg(self.data())
            .args(["--lease-secs", &o.lease_secs.to_string()])
            .args(["--max-attempts", &o.max_attempts.to_string()])
            .args(["--max-body-bytes", &o.max_body_bytes.to_string()])
            .args(["--rate", &o.rate.to_string()])
            .args(["--header-timeout-secs", &o.header_timeout_secs.to_string()])
            .args(o.job_rays.map(|r| format!("--job-rays={r}")))
            .args(
                o.max_bake_input_bytes
                    .map(|b| format!("--max-bake-input-bytes={b}")),
            )
            .args(o.blobs.as_ref().map(|b| format!("--blobs={b}")))
            .args(o.database.as_ref().map(|d| format!("--database={d}")))
            .args(
                o.tls
                    .iter()
                    .flat_map(|(cert, key)| {
                        [
                            "--tls-cert".into(),
                            cert.into(),
                            "--tls-key".into(),
                            key.into(),
                        ]
                    })
                    .collect::<Vec<std::ffi::OsString>>(),
            )
            .env("AOBAKE_ADMIN_TOKEN", ADMIN)
            .stdout(out)
            .stderr(log)
            .spawn()
            .expect("aobake serve starts");
        self.server = Some(child);
        let started = Instant::now();
        loop {
            if let Ok(url) = std::fs::read_to_string(&url_file) {
                self.url = url.trim().to_owned();
                break;
            }
            assert!(
                started.elapsed() < Duration::from_secs(30),
                "the server did not start: {}",
                self.server_log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// SIGKILLs the server.
    pub fn kill_server(&mut self) {
        if let Some(mut s) = self.server.take() {
            let _ = s.kill();
            let _ = s.wait();
        }
    }

    /// The server's `https://` address (`listening on https://…`, when
    /// started with [`Options::tls`]).
    pub fn public_url(&self) -> String {
        let out = std::fs::read_to_string(self.dir.path().join("server.out")).unwrap_or_default();
        out.split_whitespace()
            .find(|w| w.starts_with("https://"))
            .unwrap_or_else(|| panic!("the server does not say it speaks https: {out}"))
            .to_owned()
    }

    /// The server's stderr so far.
    pub fn server_log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("server.log")).unwrap_or_default()
    }

    /// A token with these scopes.
    pub fn token(&self, scopes: &[&str]) -> String {
        let r = self
            .request(
                "POST",
                "/v1/tokens",
                ADMIN,
                Some(serde_json::json!({"name": "test", "scopes": scopes})),
            )
            .expect("token");
        r.1["token"].as_str().expect("token").to_owned()
    }

    /// Starts a worker process with extra environment; returns its index.
    pub fn start_worker(&mut self, env: &[(&str, &str)]) -> usize {
        self.spawn_worker(None, None, env)
    }

    /// Starts a worker process for this server on `host` of a
    /// [`netns::TestNet`], named after the host; returns its index.
    pub fn start_worker_in(&mut self, host: &netns::Host, env: &[(&str, &str)]) -> usize {
        self.spawn_worker(Some(host), None, env)
    }

    /// Starts a worker process given `servers` as its `--server` (this
    /// server's URL and others, comma-separated); returns its index.
    pub fn start_worker_for(&mut self, servers: &str) -> usize {
        self.spawn_worker(None, Some(servers), &[])
    }

    /// [`TestEnv::start_worker_for`] with `env` set for the worker.
    pub fn start_worker_at(&mut self, servers: &str, env: &[(&str, &str)]) -> usize {
        self.spawn_worker(None, Some(servers), env)
    }

    fn spawn_worker(
        &mut self,
        host: Option<&netns::Host>,
        servers: Option<&str>,
        env: &[(&str, &str)],
    ) -> usize {
        let token = self.token(&["worker"]);
        let i = self.workers.len();
        let log =
            std::fs::File::create(self.dir.path().join(format!("worker-{i}.log"))).expect("log");
        let (mut cmd, id) = match host {
            Some(h) => (h.command(binary()), h.ns.clone()),
            None => (Command::new(binary()), format!("w{i}")),
        };
        cmd.args([
            "worker",
            "--server",
            servers.unwrap_or(&self.url),
            "--id",
            &id,
        ])
        .args([
            "--heartbeat-secs",
            &(self.options.lease_secs / 4.0).to_string(),
        ])
        .env("AOBAKE_TOKEN", token)
        .env("RAYON_NUM_THREADS", "1")
        // Every checkpoint saved: the crash tests resume from them.
        .env("AOBAKE_CHECKPOINT_SECS", "0")
        .stdout(Stdio::null())
        .stderr(log);
        for (k, v) in env {
            cmd.env(k, v);
        }
        self.workers
            .push(Some(cmd.spawn().expect("aobake worker starts")));
        i
    }

    /// SIGKILLs worker `i`.
    pub fn kill_worker(&mut self, i: usize) {
        if let Some(mut w) = self.workers[i].take() {
            let _ = w.kill();
            let _ = w.wait();
        }
    }

    /// Sends `signal` to worker `i` (SIGSTOP, SIGCONT, SIGTERM).
    pub fn signal_worker(&self, i: usize, signal: nix::sys::signal::Signal) {
        let child = self.workers[i].as_ref().expect("a running worker");
        let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).expect("a pid"));
        nix::sys::signal::kill(pid, signal).expect("the signal is sent");
    }

    /// Whether worker `i` has exited (and reaps it).
    pub fn worker_exited(&mut self, i: usize) -> bool {
        match &mut self.workers[i] {
            Some(c) => c.try_wait().ok().flatten().is_some(),
            None => true,
        }
    }

    /// Everything the workers printed.
    pub fn worker_logs(&self) -> String {
        (0..self.workers.len())
            .map(|i| {
                std::fs::read_to_string(self.dir.path().join(format!("worker-{i}.log")))
                    .unwrap_or_default()
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// A request with a JSON body; returns the status and the JSON answer
    /// (or the text as a JSON string).
    pub fn request(
        &self,
        method: &str,
        path: &str,
        token: &str,
        body: Option<Value>,
    ) -> Result<(u16, Value), String> {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(60)))
            .build()
            .into();
        let uri = format!("{}{path}", self.url);
        let req = ureq::http::Request::builder()
            .method(method)
            .uri(&uri)
            .header("authorization", format!("Bearer {token}"));
        let res = match body {
            Some(b) => agent.run(
                req.header("content-type", "application/json")
                    .body(b.to_string())
                    .map_err(|e| e.to_string())?,
            ),
            None => agent.run(req.body(()).map_err(|e| e.to_string())?),
        };
        let mut res = res.map_err(|e| e.to_string())?;
        let status = res.status().as_u16();
        let text = res.body_mut().read_to_string().unwrap_or_default();
        Ok((
            status,
            serde_json::from_str(&text).unwrap_or(Value::String(text)),
        ))
    }

    /// Posts raw bytes with a content type.
    pub fn post_bytes(
        &self,
        path: &str,
        token: &str,
        content_type: &str,
        bytes: &[u8],
    ) -> (u16, Value, Vec<(String, String)>) {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .build()
            .into();
        let mut res = agent
            .post(format!("{}{path}", self.url))
            .header("authorization", format!("Bearer {token}"))
            .header("content-type", content_type)
            .send(bytes)
            .expect("request");
        let headers = res
            .headers()
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_str().unwrap_or("").to_owned()))
            .collect();
        let status = res.status().as_u16();
        let text = res.body_mut().read_to_string().unwrap_or_default();
        (
            status,
            serde_json::from_str(&text).unwrap_or(Value::String(text)),
            headers,
        )
    }

    /// Runs the `aobake` CLI against this server with the admin token.
    pub fn aobake(&self, args: &[&str]) -> Output {
        self.aobake_command(args).output().expect("aobake runs")
    }

    /// The command [`TestEnv::aobake`] runs, to spawn.
    pub fn aobake_command(&self, args: &[&str]) -> Command {
        let mut command = Command::new(binary());
        command
            .args(args)
            .env("AOBAKE_SERVER", &self.url)
            .env("AOBAKE_TOKEN", ADMIN)
            .current_dir(self.dir.path());
        command
    }

    /// Waits until the bake ends (done, failed or cancelled), or panics
    /// after `timeout`.
    pub fn wait_bake(&self, id: i64, timeout: Duration) -> Value {
        self.wait_for_bake(id, timeout, "finish", |b| {
            matches!(b["state"].as_str(), Some("done" | "failed" | "cancelled"))
        })
    }

    /// Waits until at least `jobs` of the bake's jobs are done (mid-bake,
    /// for a test to disturb it), or panics after `timeout` or when the
    /// bake failed.
    pub fn wait_jobs_done(&self, id: i64, jobs: i64, timeout: Duration) -> Value {
        self.wait_for_bake(id, timeout, &format!("reach {jobs} jobs done"), |b| {
            assert_ne!(b["state"], "failed", "{b}");
            b["jobs_done"].as_i64().unwrap_or(0) >= jobs
        })
    }

    /// Polls the bake until `reached` says so; returns the bake then, or
    /// panics after `timeout` saying what it waited to `what`.
    pub fn wait_for_bake(
        &self,
        id: i64,
        timeout: Duration,
        what: &str,
        reached: impl Fn(&Value) -> bool,
    ) -> Value {
        let started = Instant::now();
        loop {
            let (status, b) = self
                .request("GET", &format!("/v1/bakes/{id}"), ADMIN, None)
                .expect("status");
            assert_eq!(status, 200, "{b}");
            if reached(&b) {
                return b;
            }
            assert!(
                started.elapsed() < timeout,
                "bake {id} did not {what} in {timeout:?}: {b}\nserver: {}\nworkers: {}",
                self.server_log(),
                self.worker_logs()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for TestEnv {
    fn drop(&mut self) {
        for i in 0..self.workers.len() {
            self.kill_worker(i);
        }
        self.kill_server();
    }
}

/// An S3-compatible server on a free loopback port (moto's `moto_server`,
/// which `.ci/run` installs; `AOBAKE_MOTO_SERVER` names another program),
/// with an empty bucket; stopped when dropped. A machine without it fails
/// the test that asks for it, never skips it.
#[derive(Debug)]
pub struct TestS3 {
    child: Child,
    /// `s3://BUCKET/PREFIX?…`, what `aobake serve --blobs` takes.
    pub url: String,
    host: Option<netns::Host>,
    addr: String,
    port: u16,
}

/// An `Authorization` header moto takes (it checks no signature, but
/// refuses some requests without one).
const MOTO_AUTH: &str = "AWS4-HMAC-SHA256 Credential=test/20260101/us-east-1/s3/aws4_request, SignedHeaders=host, Signature=0";

impl TestS3 {
    /// Starts the server and makes the bucket.
    pub fn start() -> Self {
        Self::start_on(None)
    }

    /// Starts one on `host` of a [`netns::TestNet`], on its address.
    pub fn start_in(host: &netns::Host) -> Self {
        Self::start_on(Some(host))
    }

    fn start_on(host: Option<&netns::Host>) -> Self {
        let (addr, port) = match host {
            Some(h) => (h.addr.clone(), 9000),
            None => {
                let port = std::net::TcpListener::bind("127.0.0.1:0")
                    .and_then(|l| l.local_addr())
                    .expect("a free port")
                    .port();
                ("127.0.0.1".to_owned(), port)
            }
        };
        let child = Self::spawn(host, &addr, port);
        Self {
            child,
            url: format!(
                "s3://aobake-test/blobs?endpoint=http://{addr}:{port}&allow_http=true\
                 &region=us-east-1&access_key_id=test&secret_access_key=test"
            ),
            host: host.cloned(),
            addr,
            port,
        }
    }

    /// Starts it again where it was without its bucket: an S3 server
    /// restarted without its data, or a bucket deleted.
    pub fn start_again_without_bucket(&mut self) {
        self.stop();
        self.child = Self::spawn_with(self.host.as_ref(), &self.addr, self.port, false);
    }

    /// Makes the (empty) bucket again.
    pub fn make_bucket(&self) {
        let bucket = format!("http://{}:{}/aobake-test", self.addr, self.port);
        ureq::put(&bucket)
            .send_empty()
            .expect("the bucket made again");
    }

    /// The URL of a blob's object (no credentials: moto does not ask).
    fn object(&self, digest: &str) -> String {
        format!(
            "http://{}:{}/aobake-test/blobs/{}/{digest}",
            self.addr,
            self.port,
            &digest[..2]
        )
    }

    /// Deletes a blob's object behind the server's back (an object a
    /// lifecycle rule expired).
    pub fn delete_blob(&self, digest: &str) {
        ureq::delete(&self.object(digest))
            .header("authorization", MOTO_AUTH)
            .call()
            .expect("the object deleted");
    }

    /// Writes other bytes under a blob's name behind the server's back (a
    /// corrupted object).
    pub fn overwrite_blob(&self, digest: &str, bytes: &[u8]) {
        ureq::put(&self.object(digest))
            .header("authorization", MOTO_AUTH)
            .send(bytes)
            .expect("the object written");
    }

    /// Runs moto on `addr:port` and makes the (empty) bucket.
    fn spawn(host: Option<&netns::Host>, addr: &str, port: u16) -> Child {
        Self::spawn_with(host, addr, port, true)
    }

    /// Runs moto on `addr:port`, with the (empty) bucket when `bucket`.
    fn spawn_with(host: Option<&netns::Host>, addr: &str, port: u16, bucket: bool) -> Child {
        let program = std::env::var("AOBAKE_MOTO_SERVER").unwrap_or_else(|_| "moto_server".into());
        let mut command = match host {
            Some(h) => h.command(&program),
            None => Command::new(&program),
        };
        let child = command
            .args(["-H", addr, "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "{program}: {e}; the S3 blob tests need moto's server \
                     (pip install 'moto[server]', as .ci/run does)"
                )
            });
        // Up when it answers; the bucket then (moto takes unsigned requests).
        let started = Instant::now();
        let url = format!("http://{addr}:{port}/aobake-test");
        loop {
            let answer = if bucket {
                ureq::put(&url).send_empty()
            } else {
                // Any answer (the missing bucket's 404) means it is up.
                match ureq::get(&url).call() {
                    Err(ureq::Error::StatusCode(_)) => break,
                    other => other,
                }
            };
            match answer {
                Ok(_) => break,
                Err(ureq::Error::StatusCode(code)) => panic!("creating the bucket: {code}"),
                Err(_) => {}
            }
            assert!(
                started.elapsed() < Duration::from_secs(30),
                "{program} did not start on port {port}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        child
    }

    /// Kills the server, as an outage would (moto keeps its objects in
    /// memory: they are gone).
    pub fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Starts it again where it was, with an empty bucket (the end of an
    /// outage that lost the objects).
    pub fn start_again(&mut self) {
        self.stop();
        self.child = Self::spawn(self.host.as_ref(), &self.addr, self.port);
    }
}

impl Drop for TestS3 {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A throwaway PostgreSQL server for tests: `initdb` into a temporary
/// directory and `pg_ctl start` on a free port (as the `postgres` user
/// when running as root, since PostgreSQL refuses to run as root).
/// Stopped on drop.
#[derive(Debug)]
pub struct TestPostgres {
    dir: tempfile::TempDir,
    bin: PathBuf,
    as_postgres: bool,
    /// The host whose namespace it runs in, if not this one's.
    host: Option<netns::Host>,
    /// The address it listens on.
    addr: String,
    port: u16,
    /// Connection URL.
    pub url: String,
}

impl TestPostgres {
    fn run(&self, program: &str, args: &[&str]) -> std::process::Output {
        let exe = self.bin.join(program);
        let mut cmd = match (&self.host, self.as_postgres) {
            (Some(h), true) => {
                let mut c = h.command("runuser");
                c.args(["-u", "postgres", "--"]).arg(&exe);
                c
            }
            (Some(h), false) => h.command(&exe),
            (None, true) => {
                let mut c = Command::new("runuser");
                c.args(["-u", "postgres", "--"]).arg(&exe);
                c
            }
            (None, false) => Command::new(&exe),
        };
        cmd.args(args)
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", exe.display()))
    }

    /// Starts one. PostgreSQL 15's binaries must be installed (`.ci/run`
    /// installs Debian's `postgresql`); their folder is `pg_config
    /// --bindir`.
    pub fn start() -> Self {
        Self::start_on(None)
    }

    /// Starts one on `host` of a [`netns::TestNet`], on its address and
    /// PostgreSQL's port, taking any client on the network.
    pub fn start_in(host: &netns::Host) -> Self {
        Self::start_on(Some(host.clone()))
    }

    fn start_on(host: Option<netns::Host>) -> Self {
        let bindir = Command::new("pg_config")
            .arg("--bindir")
            .output()
            .expect("pg_config is missing: install PostgreSQL (apt-get install postgresql)");
        let bin = PathBuf::from(String::from_utf8_lossy(&bindir.stdout).trim());
        let as_postgres = Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
        let dir = tempfile::tempdir().unwrap();
        if as_postgres {
            let ids = |flag: &str| -> u32 {
                let o = Command::new("id")
                    .args([flag, "postgres"])
                    .output()
                    .unwrap();
                String::from_utf8_lossy(&o.stdout).trim().parse().unwrap()
            };
            std::os::unix::fs::chown(dir.path(), Some(ids("-u")), Some(ids("-g"))).unwrap();
        }
        let (addr, port) = match &host {
            // The namespace is the host's own: the usual port is free.
            Some(h) => (h.addr.clone(), 5432),
            None => {
                let port = std::net::TcpListener::bind("127.0.0.1:0")
                    .unwrap()
                    .local_addr()
                    .unwrap()
                    .port();
                ("127.0.0.1".to_owned(), port)
            }
        };
        let data = dir.path().join("pg");
        let data = data.to_str().unwrap();
        let pg = Self {
            bin,
            as_postgres,
            url: format!("postgres://aobake@{addr}:{port}/postgres"),
            host,
            addr,
            port,
            dir,
        };
        let out = pg.run(
            "initdb",
            &["-D", data, "-A", "trust", "-U", "aobake", "--no-sync"],
        );
        assert!(
            out.status.success(),
            "initdb: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        if pg.host.is_some() {
            // Clients come from the other hosts of the test network.
            use std::io::Write as _;
            std::fs::OpenOptions::new()
                .append(true)
                .open(pg.dir.path().join("pg/pg_hba.conf"))
                .and_then(|mut f| f.write_all(b"host all all 0.0.0.0/0 trust\n"))
                .expect("pg_hba.conf");
        }
        pg.start_again();
        pg
    }

    /// Stops the server at once (`pg_ctl stop -m immediate`), as a crash
    /// or a restart would.
    pub fn stop(&self) {
        let data = self.dir.path().join("pg");
        let out = self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-m",
                "immediate",
                "-w",
                "stop",
            ],
        );
        assert!(
            out.status.success(),
            "pg_ctl stop: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// Starts the server on its data and port (after [`TestPostgres::stop`]).
    pub fn start_again(&self) {
        let data = self.dir.path().join("pg");
        let options = format!(
            "-p {} -k {} -c listen_addresses={} -c fsync=off",
            self.port,
            self.dir.path().display(),
            self.addr
        );
        let log = self.dir.path().join("pg.log");
        let out = self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-o",
                &options,
                "-l",
                log.to_str().unwrap(),
                "-w",
                "start",
            ],
        );
        assert!(
            out.status.success(),
            "pg_ctl start: {}{}",
            String::from_utf8_lossy(&out.stderr),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
    }
}

impl Drop for TestPostgres {
    fn drop(&mut self) {
        let data = self.dir.path().join("pg");
        let _ = self.run(
            "pg_ctl",
            &["-D", data.to_str().unwrap(), "-m", "immediate", "stop"],
        );
    }
}

/// The boundary of [`multipart`] bodies.
const BOUNDARY: &str = "aobake-test-boundary";

/// A `multipart/form-data` body of `parts` (field name, file name,
/// bytes) and its content type, as a browser's form or `curl -F` sends
/// one.
pub fn multipart(parts: &[(&str, &str, &[u8])]) -> (String, Vec<u8>) {
    let mut body = Vec::new();
    for (name, file, bytes) in parts {
        body.extend(format!(
            "--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"{name}\"; filename=\"{file}\"\r\nContent-Type: application/octet-stream\r\n\r\n"
        ).bytes());
        body.extend(*bytes);
        body.extend(b"\r\n");
    }
    body.extend(format!("--{BOUNDARY}--\r\n").bytes());
    (format!("multipart/form-data; boundary={BOUNDARY}"), body)
}
