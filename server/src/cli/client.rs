//! The service from the command line: `aobake submit`, `status`, `fetch`
//! and `token create` (`worker` is in `worker.rs`). The server and token come from flags, then
//! `AOBAKE_SERVER` and `AOBAKE_TOKEN`, then the files `aobake serve`
//! writes into its data directory (`aobake-data/server.url`,
//! `aobake-data/admin.token`), so a second terminal beside `aobake serve`
//! needs neither.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context as _, bail};
use aobake_core::{Limits, asset::report::BakeReport, bake::UploadBytes, method::Method};
use serde_json::{Value, json};

use super::params::BakeRequestArgs;

/// Where the service is.
#[derive(Debug, Clone, clap::Args)]
pub(super) struct Conn {
    /// The server's URL. Default: `AOBAKE_SERVER`, else the URL `aobake
    /// serve` wrote into `aobake-data/server.url`.
    #[arg(long, env = "AOBAKE_SERVER")]
    server: Option<String>,
    /// A bearer token. Default: `AOBAKE_TOKEN`, else
    /// `aobake-data/admin.token`.
    #[arg(long, env = "AOBAKE_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// The data directory of a local `aobake serve`, read for the defaults
    /// above.
    #[arg(long, env = "AOBAKE_DATA", default_value = "aobake-data")]
    data: PathBuf,
}

/// A blocking client of the API.
#[derive(Debug)]
pub(crate) struct Api {
    base: String,
    auth: String,
    agent: ureq::Agent,
}

/// A status the API answered with, and its problem+json detail.
#[derive(Debug, thiserror::Error)]
#[error("the server answered {status}: {detail}")]
pub(super) struct ApiStatus {
    pub status: u16,
    pub detail: String,
}

/// Ends the process with this exit code (after printing the message).
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct Exit {
    /// The code.
    pub code: u8,
    /// What to print.
    pub message: String,
}

impl Conn {
    fn api(&self) -> anyhow::Result<Api> {
        let read = |name: &str| std::fs::read_to_string(self.data.join(name)).ok();
        let server = self
            .server
            .clone()
            .or_else(|| read("server.url"))
            .unwrap_or_else(|| "http://127.0.0.1:8080".to_owned());
        let token = self
            .token
            .clone()
            .or_else(|| read("admin.token"))
            .context("no token: pass --token or set AOBAKE_TOKEN")?;
        Ok(Api::new(server.trim(), token.trim()))
    }
}

impl Api {
    pub(crate) fn new(base: &str, token: &str) -> Self {
        Self {
            base: base.trim_end_matches('/').to_owned(),
            auth: format!("Bearer {token}"),
            agent: ureq::Agent::config_builder()
                .timeout_global(Some(Duration::from_secs(600)))
                .http_status_as_error(false)
                .build()
                .into(),
        }
    }

    fn check(
        &self,
        res: Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    ) -> anyhow::Result<ureq::http::Response<ureq::Body>> {
        let mut res = res.with_context(|| format!("cannot reach {}", self.base))?;
        let status = res.status().as_u16();
        if status >= 400 {
            let body = res.body_mut().read_to_string().unwrap_or_default();
            let detail = serde_json::from_str::<Value>(&body)
                .ok()
                .and_then(|v| v["detail"].as_str().map(str::to_owned))
                .unwrap_or(body);
            return Err(ApiStatus { status, detail }.into());
        }
        Ok(res)
    }

    fn json(&self, res: ureq::http::Response<ureq::Body>) -> anyhow::Result<Value> {
        let mut res = res;
        Ok(res.body_mut().with_config().limit(1 << 30).read_json()?)
    }

    pub(super) fn get(&self, path: &str) -> anyhow::Result<Value> {
        let res = self.check(
            self.agent
                .get(format!("{}{path}", self.base))
                .header("authorization", &self.auth)
                .call(),
        )?;
        self.json(res)
    }

    fn get_bytes(&self, path: &str) -> anyhow::Result<Vec<u8>> {
        let mut res = self.check(
            self.agent
                .get(format!("{}{path}", self.base))
                .header("authorization", &self.auth)
                .call(),
        )?;
        Ok(res.body_mut().with_config().limit(u64::MAX).read_to_vec()?)
    }

    pub(crate) fn post(&self, path: &str, body: &Value) -> anyhow::Result<Value> {
        let res = self.check(
            self.agent
                .post(format!("{}{path}", self.base))
                .header("authorization", &self.auth)
                .send_json(body),
        )?;
        self.json(res)
    }

    /// Uploads a character or clip file (a bundle when it has side files)
    /// under the file's name.
    pub(crate) fn upload(
        &self,
        path: &str,
        upload: &UploadBytes,
        name: &str,
    ) -> anyhow::Result<Value> {
        let content_type = if upload.is_bundle() {
            "application/vnd.aobake.bundle"
        } else {
            "model/gltf-binary"
        };
        let res = self.check(
            self.agent
                .post(format!("{}{path}", self.base))
                .query("name", name)
                .header("authorization", &self.auth)
                .header("content-type", content_type)
                .send(&upload.to_blob()[..]),
        )?;
        self.json(res)
    }
}

/// Arguments of `aobake submit`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Unset parameters keep the method's defaults; `aobake params --method M` prints them all, and `--param KEY=VALUE` sets any of them."
)]
pub(super) struct SubmitArgs {
    #[command(flatten)]
    request: BakeRequestArgs,
    /// Higher runs first.
    #[arg(long, default_value_t = 0)]
    priority: i64,
    /// Wait for the bake to finish, with a progress bar, and print its
    /// summary.
    #[arg(long)]
    wait: bool,
    #[command(flatten)]
    conn: Conn,
}

/// A file's name as the server keeps it for people to read.
fn display_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// Uploads the files, submits the bake and returns the bake as the API
/// shows it.
pub(super) fn submit_files(
    api: &Api,
    file: &Path,
    clips: &[PathBuf],
    method: Method,
    params: serde_json::Map<String, Value>,
    priority: i64,
) -> anyhow::Result<Value> {
    let limits = Limits::default();
    let character = super::load::upload(file, &limits)?;
    let c = api
        .upload("/v1/characters", &character, &display_name(file))
        .with_context(|| format!("cannot upload {}", file.display()))?;
    let digest = c["digest"].as_str().context("no digest")?.to_owned();
    let mut clip_digests = Vec::new();
    for path in clips {
        let u = super::load::upload(path, &limits)?;
        let r = api
            .upload(
                &format!("/v1/clips?character={digest}"),
                &u,
                &display_name(path),
            )
            .with_context(|| format!("cannot upload {}", path.display()))?;
        clip_digests.push(r["digest"].clone());
    }
    api.post(
        "/v1/bakes",
        &json!({
            "character": digest,
            "clips": clip_digests,
            "method": method.name(),
            "params": params,
            "priority": priority,
        }),
    )
}

pub(super) fn submit(args: &SubmitArgs) -> anyhow::Result<()> {
    let api = args.conn.api()?;
    let r = &args.request;
    let overrides = r.params.overrides(r.method)?;
    // Validate here too, so a typo fails before the upload.
    aobake_core::bake::BakeParams::with_overrides(r.method, &overrides)?;
    let bake = submit_files(&api, &r.file, &r.clips, r.method, overrides, args.priority)?;
    let id = bake["id"].as_i64().context("no bake id")?;
    println!(
        "bake {id}: key {}, {}",
        bake["key"].as_str().unwrap_or("?"),
        bake["state"].as_str().unwrap_or("?")
    );
    if args.wait {
        wait(&api, id)?;
    }
    Ok(())
}

/// Follows a bake until it ends, with a progress bar; prints the summary.
fn wait(api: &Api, id: i64) -> anyhow::Result<()> {
    let bar = super::trace::progress_bar(1, "baking");
    loop {
        let b = api.get(&format!("/v1/bakes/{id}"))?;
        let (done, total) = (
            b["progress"]["done"].as_u64().unwrap_or(0),
            b["progress"]["total"].as_u64().unwrap_or(1),
        );
        bar.set_length(total);
        bar.set_position(done);
        bar.set_message(running_jobs(&b));
        match b["state"].as_str().unwrap_or("") {
            "done" => {
                bar.finish_and_clear();
                let report: BakeReport =
                    serde_json::from_slice(&api.get_bytes(&format!("/v1/bakes/{id}/report"))?)?;
                println!(
                    "bake {id} done: asset {}",
                    b["asset"].as_str().unwrap_or("?")
                );
                print!("{}", super::bake::summary(&report));
                return Ok(());
            }
            "failed" | "cancelled" => {
                bar.finish_and_clear();
                bail!(
                    "bake {id} {}: {}",
                    b["state"].as_str().unwrap_or("?"),
                    b["error"].as_str().unwrap_or("no reason recorded")
                );
            }
            _ => std::thread::sleep(Duration::from_millis(500)),
        }
    }
}

/// The running jobs of a bake view and how far each is (`fit 2/4,
/// unseen 1/4`), or the bake's state when none runs.
fn running_jobs(bake: &serde_json::Value) -> String {
    let running: Vec<String> = bake["jobs"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|j| j["state"] == "running")
        .map(|j| {
            format!(
                "{} {}/{}",
                j["kind"].as_str().unwrap_or("job"),
                j["progress"].as_i64().unwrap_or(0),
                j["work"].as_i64().unwrap_or(1)
            )
        })
        .collect();
    if running.is_empty() {
        bake["state"].as_str().unwrap_or("").to_owned()
    } else {
        running.join(", ")
    }
}

/// Arguments of `aobake status`.
#[derive(Debug, clap::Args)]
pub(super) struct StatusArgs {
    /// The bake id.
    id: i64,
    /// Print the whole JSON, every job included.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    conn: Conn,
}

pub(super) fn status(args: &StatusArgs) -> anyhow::Result<()> {
    let b = args.conn.api()?.get(&format!("/v1/bakes/{}", args.id))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&b)?);
        return Ok(());
    }
    let jobs = b["jobs"].as_array().cloned().unwrap_or_default();
    let mut states: std::collections::BTreeMap<String, usize> = Default::default();
    for j in &jobs {
        *states
            .entry(j["state"].as_str().unwrap_or("?").to_owned())
            .or_default() += 1;
    }
    println!(
        "bake {}: {} ({} of {} units), {} {}; key {}",
        args.id,
        b["state"].as_str().unwrap_or("?"),
        b["progress"]["done"],
        b["progress"]["total"],
        b["method"].as_str().unwrap_or("?"),
        states
            .iter()
            .map(|(s, n)| format!("{n} {s}"))
            .collect::<Vec<_>>()
            .join(", "),
        b["key"].as_str().unwrap_or("?"),
    );
    if let Some(a) = b["asset"].as_str() {
        println!("asset {a}");
    }
    if let Some(e) = b["error"].as_str() {
        println!("error: {e}");
    }
    Ok(())
}

/// Arguments of `aobake fetch`.
#[derive(Debug, clap::Args)]
pub(super) struct FetchArgs {
    /// The bake id.
    #[arg(required_unless_present = "key", conflicts_with = "key")]
    id: Option<i64>,
    /// The bake key (what CI knows before it bakes).
    #[arg(long)]
    key: Option<String>,
    /// Where to write the asset.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    conn: Conn,
}

/// Exit code when no finished bake exists, so CI can branch on it.
pub const NOT_BAKED: u8 = 4;

pub(super) fn fetch(args: &FetchArgs) -> anyhow::Result<()> {
    let api = args.conn.api()?;
    let bake = match (&args.key, args.id) {
        (Some(key), _) => match api.get(&format!("/v1/cache/{key}")) {
            Err(e)
                if e.downcast_ref::<ApiStatus>()
                    .is_some_and(|s| s.status == 404) =>
            {
                return Err(Exit {
                    code: NOT_BAKED,
                    message: format!("no finished bake for key {key}"),
                }
                .into());
            }
            other => other?,
        },
        (None, Some(id)) => api.get(&format!("/v1/bakes/{id}"))?,
        (None, None) => bail!("give a bake id or --key"),
    };
    let Some(asset) = bake["asset"].as_str() else {
        return Err(Exit {
            code: NOT_BAKED,
            message: format!(
                "bake {} is {}, not done",
                bake["id"],
                bake["state"].as_str().unwrap_or("?")
            ),
        }
        .into());
    };
    let bytes = api.get_bytes(&format!("/v1/assets/{asset}"))?;
    if aobake_core::digest::sha256_hex(&bytes) != asset {
        bail!("the asset's bytes do not match its digest {asset}");
    }
    std::fs::write(&args.out, &bytes)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    println!(
        "wrote {} ({} bytes) from bake {}",
        args.out.display(),
        bytes.len(),
        bake["id"]
    );
    Ok(())
}

/// Arguments of `aobake token`.
#[derive(Debug, clap::Args)]
pub(super) struct TokenArgs {
    #[command(subcommand)]
    what: TokenCommand,
}

#[derive(Debug, clap::Subcommand)]
enum TokenCommand {
    /// Create a token (needs an admin token); prints it once.
    Create {
        /// Scopes: read, submit, worker, admin (repeat for several).
        #[arg(long = "scope", required = true)]
        scopes: Vec<String>,
        /// A name to recognise it by.
        #[arg(long, default_value = "cli")]
        name: String,
        #[command(flatten)]
        conn: Conn,
    },
}

pub(super) fn token(args: &TokenArgs) -> anyhow::Result<()> {
    let TokenCommand::Create { scopes, name, conn } = &args.what;
    let r = conn
        .api()?
        .post("/v1/tokens", &json!({"name": name, "scopes": scopes}))?;
    println!("{}", r["token"].as_str().context("no token in the answer")?);
    Ok(())
}
