//! A real headless Chromium over WebDriver (Debian's `chromium` and
//! `chromium-driver`, which `.ci/run` installs), for the tests that look
//! at pages: the dashboard's, and a stock three.js render of an export.

use std::net::TcpListener;
use std::os::unix::process::CommandExt as _;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder};
use serde_json::{Value, json};

/// chromedriver on a free port, killed on drop.
pub(crate) struct Driver {
    child: Child,
    pub(crate) url: String,
}

impl Driver {
    pub(crate) fn start() -> Self {
        let port = free_port();
        let binary = ["chromedriver", "/usr/bin/chromedriver"]
            .into_iter()
            .find(|b| Command::new(b).arg("--version").output().is_ok())
            .expect(
                "the dashboard test needs Chromium's WebDriver: apt-get install chromium chromium-driver",
            );
        // A process group of its own, so dropping it ends the browsers it
        // started too, even those of a session a failed test left open.
        let child = Command::new(binary)
            .arg(format!("--port={port}"))
            .process_group(0)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let url = format!("http://127.0.0.1:{port}");
        wait_for_port(port, "chromedriver");
        Self { child, url }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::killpg(
                nix::unistd::Pid::from_raw(pid),
                nix::sys::signal::Signal::SIGKILL,
            );
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A port free on 127.0.0.1 a moment ago, for a process to listen on.
pub(crate) fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Waits (up to 20 seconds) until `what` listens on `port`.
pub(crate) fn wait_for_port(port: u16, what: &str) {
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "{what} did not start"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

pub(crate) fn artifacts() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dashboard");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub(crate) async fn browser(driver: &Driver) -> Client {
    browser_with(driver, false).await
}

/// A Chromium session; with `webgl`, WebGL2 on SwiftShader (a software
/// GPU: the flags Chromium wants before it offers WebGL without one).
pub(crate) async fn browser_with(driver: &Driver, webgl: bool) -> Client {
    let mut caps = serde_json::Map::new();
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .find(|p| std::path::Path::new(p).exists());
    let mut args = vec![
        "--headless=new",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--window-size=1280,1100",
        "--no-first-run",
    ];
    if webgl {
        args.extend(["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]);
    } else {
        args.push("--disable-gpu");
    }
    let mut options = json!({ "args": args });
    if let Some(c) = chromium {
        options["binary"] = json!(c);
    }
    caps.insert("goog:chromeOptions".into(), options);
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("a Chromium session")
}

/// Runs a test's browser session to its end on a runtime of its own.
pub(crate) fn block_on<F: std::future::Future>(session: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(session)
}

pub(crate) async fn eval(c: &Client, script: &str) -> Value {
    c.execute(script, vec![]).await.unwrap()
}

/// Waits until `script` (a JavaScript expression) is truthy.
pub(crate) async fn wait_for(c: &Client, what: &str, script: &str, timeout: Duration) -> Value {
    let started = Instant::now();
    let body = format!("return ({script}) || null;");
    loop {
        let v = eval(c, &body).await;
        if !v.is_null() && v != json!(false) {
            return v;
        }
        if started.elapsed() > timeout {
            let page = eval(c, "return document.body.innerText").await;
            let _ = shot(c, &format!("timeout-{}", what.replace(' ', "-"))).await;
            panic!("timed out waiting for {what}; the page says:\n{page}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

pub(crate) async fn shot(c: &Client, name: &str) -> PathBuf {
    let png = c.screenshot().await.unwrap();
    let path = artifacts().join(format!("{name}.png"));
    std::fs::write(&path, png).unwrap();
    eprintln!("screenshot: {}", path.display());
    path
}
