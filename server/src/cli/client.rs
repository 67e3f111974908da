//! The service from the command line: `aobake submit`, `status`, `fetch`
//! and `token create` (`worker` is in `worker.rs`). The server and token come from flags, then
//! `AOBAKE_SERVER` and `AOBAKE_TOKEN`, then the files `aobake serve`
//! writes into its data directory (`aobake-data/server.url`,
//! `aobake-data/admin.token`), so a second terminal beside `aobake serve`
//! needs neither.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context as _, bail};
use aobake_api::{BakeRequest, BakeState, BakeView, Client, JobState, NewTokenRequest, TokenView};
use aobake_core::{
    Limits,
    bake::{BakeReport, screen_space::PixelSummary},
    method::Method,
};
use serde_json::Value;

use super::params::BakeRequestArgs;

/// Where the service is.
#[derive(Debug, Clone, clap::Args)]
pub(super) struct Conn {
    /// The server's URL, or a fleet's servers comma-separated (the next is
    /// asked when one cannot be reached). Default: `AOBAKE_SERVER`, else
    /// the URL `aobake serve` wrote into `aobake-data/server.url`. An
    /// https:// server's certificate must be one the machine trusts (its
    /// store; SSL_CERT_FILE or SSL_CERT_DIR replace the store).
    #[arg(long, env = "AOBAKE_SERVER", value_parser = super::common::server_list)]
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

/// Where this process's token came from (a command talks to one server
/// with one token), for an error that refuses it.
static TOKEN_SOURCE: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// Where the address of this process's latest client came from when no
/// flag or variable gave it (`DIR/server.url`, or the default), and that
/// client: set again whenever a client is made (`submit --wait` makes
/// one again when the files change).
static SERVER_SOURCE: std::sync::Mutex<Option<(String, Client)>> = std::sync::Mutex::new(None);

/// `err`, saying where its token came from when the server refused it
/// (401): a token file left by an earlier `aobake serve`, or a variable
/// set long ago, is otherwise hard to tell from a typo; and where the
/// server's address came from when it cannot be reached and no flag gave
/// it (a `server.url` that a stopped `aobake serve` left).
pub fn explain_refusal(err: anyhow::Error) -> anyhow::Error {
    let api_error = |matches: fn(&aobake_api::ApiError) -> bool| {
        err.chain().any(|cause| {
            cause
                .downcast_ref::<aobake_api::ApiError>()
                .is_some_and(matches)
        })
    };
    let refused = api_error(|e| e.status() == Some(401));
    let unreached = api_error(|e| matches!(e, aobake_api::ApiError::Transport { .. }));
    // A server that never answered at an address no flag gave.
    let stale = SERVER_SOURCE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .as_ref()
        .filter(|(_, client)| !client.answered())
        .map(|(source, _)| source.clone());
    match (TOKEN_SOURCE.get(), stale) {
        (Some(source), _) if refused => {
            err.context(format!("the server refused the token from {source}"))
        }
        (_, Some(source)) if unreached => err.context(format!(
            "the server's address came from {source}: is that server running? (--server or AOBAKE_SERVER names another)"
        )),
        _ => err,
    }
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
    /// A client made again from the files `aobake serve` writes, when it
    /// differs from `api`: a server on port 0 that restarted on another
    /// port (`DIR/server.url`), or whose restart revoked the admin token
    /// it had generated (`DIR/admin.token`). `None` when both came from
    /// flags or the environment, or nothing changed.
    fn fresh(&self, api: &Client) -> Option<Client> {
        if self.server.is_some() && self.token.is_some() {
            return None;
        }
        let (now, source) = self.build().ok()?;
        if now.same_as(api) {
            return None;
        }
        Self::remember(source, &now);
        Some(now)
    }

    fn api(&self) -> anyhow::Result<Client> {
        let (client, source) = self.build()?;
        Self::remember(source, &client);
        Ok(client)
    }

    /// Keeps where the address of `client`, the one this process now
    /// uses, came from, when no flag gave it (for [`explain_refusal`]).
    fn remember(source: Option<String>, client: &Client) {
        *SERVER_SOURCE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) =
            source.map(|s| (s, client.clone()));
    }

    /// A client from the flags and the data folder's files, and where its
    /// address came from when no flag or variable gave it.
    fn build(&self) -> anyhow::Result<(Client, Option<String>)> {
        let read = |name: &str| std::fs::read_to_string(self.data.join(name)).ok();
        let url_file = || self.data.join("server.url").display().to_string();
        let (server, source) = match &self.server {
            Some(s) => (s.clone(), None),
            None => match read("server.url") {
                Some(s) => (s, Some(url_file())),
                None => (
                    "http://127.0.0.1:8080".to_owned(),
                    Some(format!(
                        "the default (no --server, AOBAKE_SERVER or {})",
                        url_file()
                    )),
                ),
            },
        };
        let token_source = match &self.token {
            Some(_) => "--token or AOBAKE_TOKEN".to_owned(),
            None => self.data.join("admin.token").display().to_string(),
        };
        let _ = TOKEN_SOURCE.set(token_source);
        let token = self
            .token
            .clone()
            .or_else(|| read("admin.token"))
            .ok_or_else(|| Exit {
                code: super::exit::TOKEN,
                message: format!(
                    "error: no token: pass --token or set AOBAKE_TOKEN (there is no {}: run this where `aobake serve` keeps its data, or point --data at that folder)",
                    self.data.join("admin.token").display()
                ),
            })?;
        // A fleet's servers: the first asked first, the next when one
        // cannot be reached.
        let (first, others) = super::common::servers(&server)?;
        // A wait through an outage says so, rather than look like a hang.
        let client = Client::new(&first, token.trim())
            .with_fallbacks(&others)
            .with_notice(|line| eprintln!("{line}"));
        Ok((client, source))
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
    /// Print the bake as JSON (`GET /v1/bakes/{id}` without its jobs: id,
    /// key, state, asset, report, …), once submitted, or with --wait once
    /// it ended, and nothing else on stdout: for scripts.
    #[arg(long)]
    json: bool,
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
    api: &Client,
    file: &Path,
    clips: &[PathBuf],
    method: Method,
    params: serde_json::Map<String, Value>,
    priority: i64,
) -> anyhow::Result<BakeView> {
    let limits = Limits::default();
    let character = super::load::upload(file, &limits)?;
    // Every file read and the list checked before anything is sent.
    let clip_uploads = super::load::clip_uploads(clips, &limits)?;
    let c = api
        .upload_character(
            &character.to_blob(),
            character.is_bundle(),
            &display_name(file),
        )
        .with_context(|| format!("cannot upload {}", file.display()))?;
    let mut clip_digests = Vec::new();
    for (path, u) in clips.iter().zip(&clip_uploads) {
        let r = api
            .upload_clips(&c.digest, &u.to_blob(), u.is_bundle(), &display_name(path))
            .with_context(|| format!("cannot upload {}", path.display()))?;
        clip_digests.push(r.digest);
    }
    Ok(api.submit(&BakeRequest {
        clips: clip_digests,
        priority,
        ..BakeRequest::new(c.digest, method.name(), params)
    })?)
}

pub(super) fn submit(args: &SubmitArgs) -> anyhow::Result<()> {
    let api = args.conn.api()?;
    let r = &args.request;
    let overrides = r.params.overrides(r.method)?;
    // Validate here too, so a typo fails before the upload.
    aobake_core::bake::BakeParams::with_overrides(r.method, &overrides)?;
    let bake = submit_files(&api, &r.file, &r.clips, r.method, overrides, args.priority)?;
    let id = bake.bake.id;
    if !args.wait && args.json {
        println!("{}", serde_json::to_string(&bake.bake)?);
    } else if !args.json {
        println!(
            "bake {id}: key {}, {}",
            bake.bake.key,
            bake.bake.state.as_str()
        );
        if let Some(lost) = bake.rebakes {
            println!(
                "  bake {lost} with this key finished, but its asset is gone from the blob store: bake {id} makes it again"
            );
        }
    }
    if args.wait {
        wait(&args.conn, &api, id, args.json)?;
    }
    Ok(())
}

/// How long `submit --wait` goes on asking a server it cannot reach (a
/// restart, a rolling update) before it gives up; the bake goes on
/// without it.
const AWAY_FOR: Duration = Duration::from_secs(300);

/// Follows a bake until it ends, with a progress bar; prints the summary
/// (`json`: the bake's row as JSON, whatever its end).
fn wait(conn: &Conn, api: &Client, id: i64, json: bool) -> anyhow::Result<()> {
    // Ctrl-C stops the following, not the bake: say so, and how to go on.
    let server = conn
        .server
        .as_deref()
        .map(|s| format!(" --server {s}"))
        .unwrap_or_default();
    let note = interrupted_note(id, &server);
    // A second handler cannot be set (a process follows one bake); the
    // default one then stays, which only loses the note.
    let _ = ctrlc::set_handler(move || {
        eprintln!("{note}");
        std::process::exit(super::exit::INTERRUPTED);
    });
    // The time left from the jobs' own paces (`aobake_api::progress`):
    // right from the start for a bake joined half done, and not "0 s"
    // while the last slow jobs run.
    let bar = super::trace::follow_bar(1, "baking");
    let mut follow = Follow {
        bar: &bar,
        id,
        away: false,
        conn,
        api: std::cell::RefCell::new(api.clone()),
    };
    loop {
        let view = follow.ask(|api| api.bake(id))?;
        bar.set_length(u64::try_from(view.progress.total).unwrap_or(1));
        bar.set_position(u64::try_from(view.progress.done).unwrap_or(0));
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as i64);
        let left = aobake_api::progress::time_left(view.jobs.as_deref().unwrap_or_default(), now);
        // Work done again (jobs leased again after a lost lease, or run
        // again for a lost output) is counted once, and said.
        bar.set_message(format!(
            "{left}; {}{}",
            running_jobs(&view),
            redo_note(&view.progress)
        ));
        let b = &view.bake;
        if json
            && matches!(
                b.state,
                BakeState::Done | BakeState::Failed | BakeState::Cancelled
            )
        {
            bar.finish_and_clear();
            println!("{}", serde_json::to_string(b)?);
        }
        match b.state {
            BakeState::Done if json => return Ok(()),
            BakeState::Done => {
                let report = follow.ask(|api| api.report(id))?;
                bar.finish_and_clear();
                let report: BakeReport = serde_json::from_slice(&report)?;
                println!(
                    "bake {id} done: asset {}",
                    b.asset.as_deref().unwrap_or("?")
                );
                print!("{}", super::bake::summary(&report));
                // The previews' per-pixel judgement, when they have one
                // (a server whose workers draw previews).
                if let Ok(list) = follow.ask(|api| api.previews(id))
                    && let Some(pixels) = list.pixels
                    && let Ok(pixels) = serde_json::from_value::<PixelSummary>(pixels)
                {
                    print!("{}", pixels.lines());
                }
                return Ok(());
            }
            BakeState::Failed | BakeState::Cancelled => {
                bar.finish_and_clear();
                return Err(Exit {
                    code: super::exit::BAKE_FAILED,
                    message: format!(
                        "error: bake {id} {}: {}",
                        b.state.as_str(),
                        b.error.as_deref().unwrap_or("no reason recorded")
                    ),
                }
                .into());
            }
            _ => std::thread::sleep(Duration::from_millis(500)),
        }
    }
}

/// What `submit --wait` prints when Ctrl-C stops it: the bake goes on,
/// and the commands that follow or stop it (`server`: the `--server`
/// flag given, if any).
pub(super) fn interrupted_note(id: i64, server: &str) -> String {
    format!(
        "\nstopped following bake {id}; it goes on on the server.\n  follow it: aobake status {id}{server}   (or run the same submit again: it joins the bake)\n  stop it:   aobake cancel {id}{server}"
    )
}

/// A bake followed through outages of its server: says so once, and
/// again when the server answers; follows a server that moved
/// ([`Conn::fresh`]).
struct Follow<'a> {
    bar: &'a indicatif::ProgressBar,
    id: i64,
    away: bool,
    conn: &'a Conn,
    api: std::cell::RefCell<Client>,
}

impl Follow<'_> {
    /// `call`'s answer, asked again through an outage for [`AWAY_FOR`].
    fn ask<T>(
        &mut self,
        mut call: impl FnMut(&Client) -> aobake_api::client::Result<T>,
    ) -> anyhow::Result<T> {
        let (bar, away, conn, api) = (self.bar, &mut self.away, self.conn, &self.api);
        // Whether the server moved during the current window of asking.
        let moved_here = std::cell::Cell::new(false);
        // A server that `aobake serve` restarted on this data folder may
        // have a new port or a new admin token: follow it there.
        let refresh = |away: &mut bool| {
            let fresh = conn.fresh(&api.borrow());
            let moved = fresh.is_some();
            moved_here.set(moved_here.get() || moved);
            if let Some(now) = fresh {
                bar.suspend(|| {
                    eprintln!(
                        "the server was started again (its files in {} changed): following it at {}",
                        conn.data.display(),
                        now.base()
                    );
                });
                *api.borrow_mut() = now;
                *away = false;
            }
            moved
        };
        let answer = loop {
            moved_here.set(false);
            let answer = aobake_api::client::retry(
                AWAY_FOR,
                Duration::from_secs(1),
                || true,
                |e, left| {
                    if refresh(away) {
                        return;
                    }
                    if !*away {
                        bar.suspend(|| {
                            eprintln!(
                                "{e}; the bake goes on there: asking again for up to {} s",
                                left.as_secs()
                            );
                        });
                        *away = true;
                    }
                },
                || call(&api.borrow()),
            );
            // A server found where it moved gets a window of its own, not
            // what its restart left of the old one.
            if answer.is_err() && moved_here.get() {
                continue;
            }
            break answer;
        };
        // A refused token whose file a restart rewrote: ask again with it.
        let answer = match answer {
            Err(e) if e.status() == Some(401) && refresh(away) => call(&api.borrow()),
            other => other,
        };
        if answer.is_ok() && std::mem::take(&mut self.away) {
            bar.suspend(|| eprintln!("the server answers again"));
        }
        let id = self.id;
        answer.with_context(|| {
            format!("cannot follow bake {id}; it may still finish: `aobake status {id}`")
        })
    }
}

/// The running jobs of a bake view and how far each is (`fit 2/4,
/// unseen 1/4`), or the bake's state when none runs.
fn running_jobs(view: &BakeView) -> String {
    let running: Vec<String> = view
        .jobs
        .iter()
        .flatten()
        .filter(|j| j.state == JobState::Running)
        .map(|j| format!("{} {}/{}", j.kind, j.progress, j.work))
        .collect();
    if running.is_empty() {
        view.bake.state.as_str().to_owned()
    } else {
        running.join(", ")
    }
}

/// How `aobake status` and the dashboard's stage table group jobs, in
/// their order: `queued` waits for a worker (a retry too), `blocked` for
/// the jobs it needs, `failed` ran out of attempts.
const JOB_GROUPS: [&str; 6] = [
    "done",
    "running",
    "queued",
    "blocked",
    "failed",
    "cancelled",
];

/// A job state's group ([`JOB_GROUPS`]).
fn job_group(state: JobState) -> &'static str {
    match state {
        JobState::Completed => "done",
        JobState::Running => "running",
        JobState::Available | JobState::Retryable => "queued",
        JobState::Blocked => "blocked",
        JobState::Dead => "failed",
        JobState::Cancelled => "cancelled",
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
    let api = args.conn.api()?;
    if args.json {
        // The server's document as it is, fields this build does not know
        // included.
        let raw: Value =
            serde_json::from_slice(&api.get_bytes(&format!("/v1/bakes/{}", args.id))?)?;
        println!("{}", serde_json::to_string_pretty(&raw)?);
        return Ok(());
    }
    let view = api.bake(args.id)?;
    // Counted in the dashboard's groups, in its order.
    let mut states: Vec<(&str, usize)> = JOB_GROUPS.iter().map(|&g| (g, 0)).collect();
    for j in view.jobs.iter().flatten() {
        let group = job_group(j.state);
        if let Some(slot) = states.iter_mut().find(|(g, _)| *g == group) {
            slot.1 += 1;
        }
    }
    states.retain(|&(_, n)| n > 0);
    let b = &view.bake;
    println!(
        "bake {}: {} ({} of {} units{}), {}; jobs: {}; key {}",
        args.id,
        b.state.as_str(),
        view.progress.done,
        view.progress.total,
        redo_note(&view.progress),
        b.method,
        states
            .iter()
            .map(|(s, n)| format!("{n} {s}"))
            .collect::<Vec<_>>()
            .join(", "),
        b.key,
    );
    if let Some(a) = &b.asset {
        println!("asset {a}");
    }
    if let Some(e) = &b.error {
        println!("error: {e}");
    }
    Ok(())
}

/// Arguments of `aobake cancel`, `pause`, `resume` and `retry`.
#[derive(Debug, clap::Args)]
pub(super) struct ControlArgs {
    /// The bake id.
    id: i64,
    #[command(flatten)]
    conn: Conn,
}

/// Applies `action` to a bake and prints its state after.
pub(super) fn control(args: &ControlArgs, action: &str) -> anyhow::Result<()> {
    let view = args.conn.api()?.control(args.id, action)?;
    println!(
        "bake {}: {} ({} of {} units{})",
        args.id,
        view.bake.state.as_str(),
        view.progress.done,
        view.progress.total,
        redo_note(&view.progress)
    );
    Ok(())
}

/// `, N being done again` when some of a bake's units are being done
/// again (jobs leased again, or run again for lost outputs): counted once
/// in its progress, and said.
fn redo_note(progress: &aobake_api::Progress) -> String {
    match progress.redo {
        0 => String::new(),
        n => format!(", {n} being done again"),
    }
}

/// Arguments of `aobake fetch`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("which").required(true).args(["id", "key"])))]
pub(super) struct FetchArgs {
    /// The bake id (or --key).
    id: Option<i64>,
    /// The bake key (what CI knows before it bakes: `aobake key` computes
    /// it from the files and parameters).
    #[arg(long)]
    key: Option<String>,
    /// Where to write the asset.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    conn: Conn,
}

pub(super) fn fetch(args: &FetchArgs) -> anyhow::Result<()> {
    let api = args.conn.api()?;
    let view = match (&args.key, args.id) {
        (Some(key), _) => api.cached(key)?.map_err(|why| Exit {
            code: super::exit::NOT_BAKED,
            message: why,
        })?,
        (None, Some(id)) => match api.bake(id) {
            Err(e) if e.status() == Some(404) => {
                return Err(Exit {
                    code: super::exit::NOT_BAKED,
                    message: format!("no bake {id} on this server"),
                }
                .into());
            }
            other => other?,
        },
        (None, None) => bail!("give a bake id or --key"),
    };
    let bake = &view.bake;
    let Some(asset) = &bake.asset else {
        return Err(Exit {
            code: super::exit::NOT_BAKED,
            message: format!("bake {} is {}, not done", bake.id, bake.state.as_str()),
        }
        .into());
    };
    let bytes = api.asset(asset)?;
    if aobake_core::digest::sha256_hex(&bytes) != *asset {
        bail!("the asset's bytes do not match its digest {asset}");
    }
    write_whole(&args.out, &bytes)?;
    // On stderr: `--out /dev/stdout` pipes the asset alone.
    eprintln!(
        "wrote {} ({} bytes) from bake {}",
        args.out.display(),
        bytes.len(),
        bake.id
    );
    Ok(())
}

/// Writes `bytes` to `out` whole or not at all, so that a pipeline that
/// finds the file finds the asset: a temporary file beside it, renamed
/// into place (removed if anything fails). Where `out` is not a regular
/// file (`/dev/stdout`, a pipe), straight into it.
fn write_whole(out: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write as _;
    let cannot = || format!("cannot write {}", out.display());
    if std::fs::metadata(out).is_ok_and(|m| !m.is_file()) {
        return std::fs::write(out, bytes).with_context(cannot);
    }
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // A new file gets the mode any new file gets (0666 less the umask,
    // not a temporary file's 0600: a build system shares what it fetched),
    // a file replaced keeps its own.
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(dir).with_context(cannot)?;
    if let Ok(existing) = std::fs::metadata(out) {
        tmp.as_file()
            .set_permissions(existing.permissions())
            .with_context(cannot)?;
    }
    tmp.write_all(bytes).with_context(cannot)?;
    tmp.persist(out).map_err(|e| e.error).with_context(cannot)?;
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
        /// A scope: read, submit (which includes read), worker or admin
        /// (every scope). Repeat the flag for several.
        #[arg(long = "scope", required = true)]
        scopes: Vec<String>,
        /// A name to recognise it by.
        #[arg(long, default_value = "cli")]
        name: String,
        /// How long it is valid, such as `90d`, `12h` or `30min` (a CI
        /// secret that expires need not be remembered to be revoked).
        /// Default: until revoked.
        #[arg(long, value_parser = humantime::parse_duration)]
        expires_in: Option<std::time::Duration>,
        #[command(flatten)]
        conn: Conn,
    },
    /// List every token, newest first: id, name, scopes, age, when it
    /// expires and when it was last used (needs an admin token; the
    /// secrets are not stored, so not shown).
    List {
        /// Print JSON (`GET /v1/tokens`) instead of a table.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        conn: Conn,
    },
    /// Revoke a token by its id (as `token list` shows it, or a unique
    /// start of it): it is refused from its next request on (needs
    /// another admin token).
    Revoke {
        /// The token's id, or its first characters (at least 8).
        #[arg(value_parser = token_id_start)]
        id: String,
        #[command(flatten)]
        conn: Conn,
    },
}

pub(super) fn token(args: &TokenArgs) -> anyhow::Result<()> {
    match &args.what {
        TokenCommand::Create {
            scopes,
            name,
            expires_in,
            conn,
        } => {
            let created = conn.api()?.create_token(&NewTokenRequest {
                name: name.clone(),
                scopes: scopes.clone(),
                // Whole seconds, at least one.
                expires_in_secs: expires_in.map(|d| d.as_secs().max(1)),
            })?;
            println!("{}", created.token);
        }
        TokenCommand::List { json, conn } => {
            let tokens = conn.api()?.tokens()?;
            if *json {
                println!("{}", serde_json::to_string_pretty(&tokens)?);
                return Ok(());
            }
            let now = crate::auth::now_ms();
            let expires = |t: &TokenView| match t.expires_at {
                None => "never".to_owned(),
                Some(at) if at <= now => format!("expired {} ago", age(now - at)),
                Some(at) => format!("in {}", age(at - now)),
            };
            let rows: Vec<[String; 6]> = tokens
                .iter()
                .map(|t| {
                    [
                        short_id(&t.id).to_owned(),
                        t.name.clone(),
                        t.scopes.join(","),
                        format!("{} ago", age(now - t.created_at)),
                        expires(t),
                        // The token this listing is made with is in use
                        // now (its use is recorded at most once a minute).
                        if t.current {
                            "now".to_owned()
                        } else {
                            t.last_used_at
                                .map_or("never".to_owned(), |at| format!("{} ago", age(now - at)))
                        },
                    ]
                })
                .collect();
            let head = ["id", "name", "scopes", "created", "expires", "last used"];
            let lines = table(head, &rows);
            println!("{}", lines[0]);
            for (t, line) in tokens.iter().zip(&lines[1..]) {
                let this = if t.current { "  (this token)" } else { "" };
                println!("{line}{this}");
            }
        }
        TokenCommand::Revoke { id, conn } => {
            let api = conn.api()?;
            let prefix = id.to_ascii_lowercase();
            let matching: Vec<_> = api
                .tokens()?
                .into_iter()
                .filter(|t| t.id.starts_with(&prefix))
                .collect();
            let refused = |message: String| Exit {
                code: super::exit::BAD_INPUT,
                message: format!("error: {message}"),
            };
            let token = match matching.as_slice() {
                [one] => one,
                [] => {
                    return Err(refused(format!(
                        "no token's id starts with {id} (`aobake token list` shows them)"
                    ))
                    .into());
                }
                _ => {
                    return Err(refused(format!(
                        "{} tokens' ids start with {id}: give more of it",
                        matching.len()
                    ))
                    .into());
                }
            };
            api.revoke_token(&token.id)?;
            println!(
                "revoked {} ({}, {})",
                short_id(&token.id),
                token.name,
                token.scopes.join(",")
            );
        }
    }
    Ok(())
}

/// A table's lines, the head first: columns as wide as their longest
/// entry (the names serve gives its own tokens run long), two spaces
/// apart.
fn table<const N: usize>(head: [&str; N], rows: &[[String; N]]) -> Vec<String> {
    let head = head.map(String::from);
    let widths: Vec<usize> = (0..N)
        .map(|c| {
            rows.iter()
                .chain([&head])
                .map(|r| r[c].chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    std::iter::once(&head)
        .chain(rows)
        .map(|r| {
            let cells: Vec<String> = r
                .iter()
                .zip(&widths)
                .map(|(cell, &w)| format!("{cell:<w$}"))
                .collect();
            cells.join("  ").trim_end().to_owned()
        })
        .collect()
}

/// Arguments of `aobake bakes`.
#[derive(Debug, clap::Args)]
pub(super) struct BakesArgs {
    /// Only bakes of this method.
    #[arg(long)]
    method: Option<Method>,
    /// At most this many, the newest (1 to 1000).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=1000))]
    limit: u32,
    /// Print JSON (`GET /v1/bakes`) instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    conn: Conn,
}

/// `aobake bakes`: a server's newest bakes, as the dashboard's list shows
/// them.
pub(super) fn bakes(args: &BakesArgs) -> anyhow::Result<()> {
    let api = args.conn.api()?;
    let method = args.method.map(Method::name);
    if args.json {
        // The server's documents as they are, fields this build does not
        // know included.
        let path = Client::bakes_path(method, args.limit);
        let raw: Value = serde_json::from_slice(&api.get_bytes(&path)?)?;
        println!("{}", serde_json::to_string_pretty(&raw)?);
        return Ok(());
    }
    let bakes = api.bakes(method, args.limit)?;
    // Each character's file name, asked once.
    let mut names = std::collections::HashMap::new();
    for b in &bakes {
        if !names.contains_key(&b.bake.character) {
            let summary = api.character(&b.bake.character)?.summary;
            let name = summary["name"].as_str().filter(|n| !n.is_empty());
            names.insert(b.bake.character.clone(), name.map(str::to_owned));
        }
    }
    let now = crate::auth::now_ms();
    let rows: Vec<[String; 6]> = bakes
        .iter()
        .map(|v| bake_row(v, names[&v.bake.character].as_deref(), now))
        .collect();
    for line in table(
        ["bake", "state", "progress", "method", "character", "when"],
        &rows,
    ) {
        println!("{line}");
    }
    Ok(())
}

/// A bake's row in `aobake bakes` at `now` (ms), its character named
/// `character` (else by its digest's start).
fn bake_row(view: &BakeView, character: Option<&str>, now: i64) -> [String; 6] {
    let b = &view.bake;
    let progress = if view.progress.total > 0 {
        format!("{} %", 100 * view.progress.done / view.progress.total)
    } else {
        String::new()
    };
    let when = match b.finished_at {
        Some(end) => format!(
            "ended {} ago, {} after submit",
            age(now - end),
            age(end - b.created_at)
        ),
        None => format!("submitted {} ago", age(now - b.created_at)),
    };
    [
        b.id.to_string(),
        b.state.as_str().to_owned(),
        progress,
        b.method.clone(),
        character
            .unwrap_or_else(|| short_id(&b.character))
            .to_owned(),
        when,
    ]
}

/// Arguments of `aobake workers`.
#[derive(Debug, clap::Args)]
pub(super) struct WorkersArgs {
    /// Print JSON (`GET /v1/workers`) instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    conn: Conn,
}

/// `aobake workers`: the workers the server knows, as the dashboard's
/// workers page lists them.
pub(super) fn workers(args: &WorkersArgs) -> anyhow::Result<()> {
    let workers = args.conn.api()?.workers()?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&workers)?);
        return Ok(());
    }
    let now = crate::auth::now_ms();
    let rows: Vec<[String; 5]> = workers
        .iter()
        .map(|w| {
            let job = match (w.job_id, w.bake_id) {
                (Some(job), Some(bake)) => format!("bake {bake}, job {job}"),
                (Some(job), None) => format!("job {job}"),
                _ => String::new(),
            };
            [
                w.id.clone(),
                w.state.clone(),
                job,
                w.tracer.clone(),
                format!(
                    "{} ago (started {} ago)",
                    age(now - w.last_seen),
                    age(now - w.started_at)
                ),
            ]
        })
        .collect();
    for line in table(["worker", "state", "running", "tracer", "last seen"], &rows) {
        println!("{line}");
    }
    Ok(())
}

/// `token revoke ID`: the start of a token's id (hex), 8 characters at
/// least, so another is a wrong command line (exit 2).
fn token_id_start(s: &str) -> Result<String, String> {
    if s.len() < 8 || !s.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(
            "give at least the first 8 characters of the token's id, as `aobake token list` shows it"
                .to_owned(),
        );
    }
    Ok(s.to_owned())
}

/// A token id's first 12 characters, as `token list` shows it.
fn short_id(id: &str) -> &str {
    id.get(..12).unwrap_or(id)
}

/// A duration in milliseconds as a person reads an age: 40 s, 12 min,
/// 5 h, 3 days.
fn age(ms: i64) -> String {
    let s = ms.max(0) / 1000;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min", s / 60),
        3600..86_400 => format!("{} h", s / 3600),
        _ => format!("{} days", s / 86_400),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_done_again_is_said_only_when_there_is_some() {
        let progress = |redo| aobake_api::Progress {
            done: 10,
            total: 20,
            redo,
        };
        assert_eq!(redo_note(&progress(0)), "");
        assert_eq!(redo_note(&progress(3)), ", 3 being done again");
    }

    #[test]
    fn a_bakes_row_says_how_far_and_when() {
        let view = |state: &str, done: i64, total: i64, finished: Option<i64>| -> BakeView {
            serde_json::from_value(serde_json::json!({
                "id": 7, "key": "k", "character": "0123456789abcdef", "clips": [],
                "method": "grid", "params": {}, "state": state, "priority": 0,
                "total_work": total, "done_work": done, "jobs_total": 3, "jobs_done": 1,
                "asset": null, "report": null, "plot": null, "error": null,
                "created_at": 1_000, "updated_at": 1_000, "finished_at": finished,
                "progress": {"done": done, "total": total},
            }))
            .unwrap()
        };
        let now = 1_000 + 3_600_000;
        assert_eq!(
            bake_row(&view("running", 1, 3, None), Some("Fox.glb"), now),
            [
                "7",
                "running",
                "33 %",
                "grid",
                "Fox.glb",
                "submitted 1 h ago"
            ]
        );
        assert_eq!(
            bake_row(&view("done", 3, 3, Some(1_000 + 90_000)), None, now),
            [
                "7",
                "done",
                "100 %",
                "grid",
                "0123456789ab",
                "ended 58 min ago, 1 min after submit"
            ]
        );
        // No work known yet: no figure.
        assert_eq!(bake_row(&view("queued", 0, 0, None), None, now)[2], "");
    }

    /// A client made from `aobake serve`'s files is made again when a
    /// restart rewrote them (a new port, a new generated admin token), and
    /// not when nothing changed or both came from flags.
    #[test]
    fn a_client_from_the_data_folder_follows_its_files() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
        write("server.url", "http://127.0.0.1:4001\n");
        write("admin.token", "first\n");
        let conn = |server: Option<&str>, token: Option<&str>| Conn {
            server: server.map(str::to_owned),
            token: token.map(str::to_owned),
            data: dir.path().to_owned(),
        };
        let from_files = conn(None, None);
        let api = from_files.api().unwrap();
        assert_eq!(api.base(), "http://127.0.0.1:4001");
        assert!(from_files.fresh(&api).is_none(), "nothing changed");
        write("admin.token", "second\n");
        let renewed = from_files.fresh(&api).expect("a new token");
        assert_eq!(renewed.base(), "http://127.0.0.1:4001");
        write("server.url", "http://127.0.0.1:4002\n");
        let moved = from_files.fresh(&renewed).expect("a new port");
        assert_eq!(moved.base(), "http://127.0.0.1:4002");
        // Given on the command line (or in the environment): kept.
        let flags = conn(Some("http://127.0.0.1:4001"), Some("mine"));
        let api = flags.api().unwrap();
        assert!(flags.fresh(&api).is_none());
    }
}
