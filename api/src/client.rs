//! The API as blocking calls (ureq): a worker's threads and the CLI each
//! wait on one request at a time, so no async runtime is needed.

use std::time::Duration;

use serde::{Serialize, de::DeserializeOwned};
use sha2::{Digest as _, Sha256};

use crate::types::{
    BakeKey, BakeRequest, BakeView, CheckpointRef, CheckpointRequest, CompleteManyReply,
    CompleteManyRequest, CompleteRequest, Completion, FailRequest, HeartbeatReply,
    HeartbeatRequest, JobCompletion, Lease, LeaseManyRequest, LeaseRequest, Leases, NewToken,
    NewTokenRequest, Problem, TokenRequest, TokenView, Uploaded, Whoami, WorkersStopped,
};

/// The longest a call waits in all on a server that answers 429 (or 503
/// with a `Retry-After`) before it fails with that status.
const MAX_RATE_WAIT: Duration = Duration::from_secs(300);

/// The content type of a `.gltf` and its side files as one body.
pub const BUNDLE: &str = "application/vnd.aobake.bundle";

/// A failed call.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// The server answered with an error status; `problem` is its
    /// problem+json body (or, from something else on the way, the body as
    /// its detail).
    #[error("the server answered {status}: {}", problem.detail)]
    Status {
        /// HTTP status.
        status: u16,
        /// What the server said.
        problem: Box<Problem>,
    },
    /// The server could not be reached, or the connection broke.
    #[error("cannot reach {base}: {message}")]
    Transport {
        /// The server.
        base: String,
        /// What failed.
        message: String,
    },
    /// The TLS handshake with an `https://` server this client never had
    /// an answer from failed (its certificate is not trusted, it does not
    /// speak TLS, no trust store): a setup problem that waiting does not
    /// mend. Once a server has answered, a failed handshake (a proxy that
    /// serves a placeholder certificate while it starts) is a
    /// [`ApiError::Transport`] error, waited out.
    #[error("cannot talk to {base} securely: {message}; {hint}")]
    Tls {
        /// The server.
        base: String,
        /// What the handshake said.
        message: String,
        /// What to do about it.
        hint: &'static str,
    },
    /// The answer was not what the API promises.
    #[error("unexpected answer from {base}: {message}")]
    Decode {
        /// The server.
        base: String,
        /// What failed.
        message: String,
    },
}

impl ApiError {
    /// The HTTP status, when the server answered.
    pub fn status(&self) -> Option<u16> {
        match self {
            Self::Status { status, .. } => Some(*status),
            _ => None,
        }
    }

    /// 409 to a worker-protocol call: the lease is gone (expired and
    /// re-leased, or the bake was cancelled).
    pub fn is_lease_lost(&self) -> bool {
        self.status() == Some(409)
    }

    /// Worth trying again: the server was unreachable or failed (5xx).
    pub fn is_transient(&self) -> bool {
        match self {
            Self::Transport { .. } => true,
            Self::Status { status, .. } => *status >= 500,
            Self::Tls { .. } | Self::Decode { .. } => false,
        }
    }
}

/// Results of calls.
pub type Result<T, E = ApiError> = std::result::Result<T, E>;

impl ApiError {
    /// Worth waiting out: the server unreachable (restarting, a rolling
    /// update), or a gateway's or a recovering server's 502, 503 or 504.
    /// A 500 is more often a fault that repeats.
    pub fn is_outage(&self) -> bool {
        match self {
            Self::Transport { .. } => true,
            Self::Status { status, .. } => matches!(status, 502..=504),
            Self::Tls { .. } | Self::Decode { .. } => false,
        }
    }
}

/// Tries `call` again while it fails transiently: an outage
/// ([`ApiError::is_outage`]) for up to `window` from the first try and
/// while `keep_on()` says so, any other 5xx three times in all. The waits
/// start at `first` and double up to 5 s; `waiting` hears each error
/// before its wait, with the time left in the window. A 409 (a lease
/// gone), any 4xx, or the window's end gives the error back.
pub fn retry<T>(
    window: Duration,
    first: Duration,
    mut keep_on: impl FnMut() -> bool,
    mut waiting: impl FnMut(&ApiError, Duration),
    mut call: impl FnMut() -> Result<T>,
) -> Result<T> {
    let started = std::time::Instant::now();
    let (mut wait, mut tries) = (first, 0);
    loop {
        tries += 1;
        match call() {
            Err(e) if e.is_transient() => {
                let left = window.saturating_sub(started.elapsed());
                let more = if e.is_outage() {
                    left >= wait
                } else {
                    tries < 3
                };
                if !more || !keep_on() {
                    return Err(e);
                }
                waiting(&e, left);
            }
            other => return other,
        }
        std::thread::sleep(wait);
        wait = (wait * 2).min(Duration::from_secs(5));
    }
}

type Response = ureq::http::Response<ureq::Body>;

/// An HTTP agent whose calls each take at most `timeout`, every status an
/// answer (the client reads problems itself). `https://` servers are
/// checked against the system's trust store (with `SSL_CERT_FILE` or
/// `SSL_CERT_DIR`, those certificates), so a studio's own CA works as the
/// machine has it.
pub fn agent(timeout: Duration) -> ureq::Agent {
    ureq::Agent::config_builder()
        .timeout_global(Some(timeout))
        .http_status_as_error(false)
        .tls_config(
            ureq::tls::TlsConfig::builder()
                .root_certs(ureq::tls::RootCerts::PlatformVerifier)
                .build(),
        )
        .build()
        .into()
}

/// The servers a client may ask: one, or several of one fleet (they
/// share a database and blob store), the one that answered last first.
#[derive(Debug)]
struct Servers {
    urls: Vec<String>,
    current: std::sync::atomic::AtomicUsize,
    /// Whether a server has answered this client (after which a failed
    /// handshake is an outage, not a setup problem).
    answered: std::sync::atomic::AtomicBool,
}

impl Servers {
    fn new(urls: Vec<String>) -> Self {
        Self {
            urls,
            current: std::sync::atomic::AtomicUsize::new(0),
            answered: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// The index of the server asked first.
    fn index(&self) -> usize {
        self.current.load(std::sync::atomic::Ordering::Relaxed) % self.urls.len()
    }

    fn current(&self) -> &str {
        &self.urls[self.index()]
    }
}

/// The hint for a failed handshake without a more precise one.
const HANDSHAKE_FAILED: &str = "the TLS handshake failed";

/// What to do about `e` when it is a failed TLS handshake (rustls' own
/// error, or one an I/O error carries); `None` for any other error. A
/// failed handshake sent no request.
fn tls_failure(e: &ureq::Error) -> Option<&'static str> {
    let rustls = match e {
        ureq::Error::Rustls(r) => r,
        ureq::Error::Tls(_) => return Some(HANDSHAKE_FAILED),
        ureq::Error::Io(io) => io.get_ref()?.downcast_ref::<rustls::Error>()?,
        _ => return None,
    };
    Some(match rustls {
        // webpki's error, which rustls carries as an opaque one.
        rustls::Error::InvalidCertificate(rustls::CertificateError::Other(other))
            if matches!(
                other.0.downcast_ref::<webpki::Error>(),
                Some(webpki::Error::CaUsedAsEndEntity)
            ) =>
        {
            "it presents a CA's certificate as its own: give the server a certificate of its own, signed by a CA this machine trusts"
        }
        rustls::Error::InvalidCertificate(
            rustls::CertificateError::NotValidForName
            | rustls::CertificateError::NotValidForNameContext { .. },
        ) => {
            "its certificate does not name the host of this address (the names it has are in its subjectAltName): use an address it names, or give the server a certificate that names this host"
        }
        rustls::Error::InvalidCertificate(
            rustls::CertificateError::Expired | rustls::CertificateError::ExpiredContext { .. },
        ) => {
            "its certificate has expired: the server needs a renewed one (aobake serve reads it again on SIGHUP)"
        }
        rustls::Error::InvalidCertificate(_) => {
            "its certificate is not one this machine trusts: add the CA that signed it to the system's trust store, or name a bundle that holds it (and the public roots, if other servers need them) with SSL_CERT_FILE; a self-signed certificate is its own CA, so the bundle may be the certificate itself"
        }
        rustls::Error::InvalidMessage(_) | rustls::Error::InappropriateMessage { .. } => {
            "it does not answer in TLS: is it an http:// address?"
        }
        rustls::Error::General(_) => {
            "no certificate could be checked: the system's trust store is empty, or SSL_CERT_FILE or SSL_CERT_DIR names no certificates"
        }
        _ => HANDSHAKE_FAILED,
    })
}

/// Whether a request failed before any server could have seen it (no
/// connection was made), so another server of the fleet may take it as it
/// is: a request that timed out or broke after it was sent may have been
/// done, and is left to [`retry`] on the same server.
fn never_arrived(e: &ureq::Error) -> bool {
    use std::io::ErrorKind;
    match e {
        ureq::Error::ConnectionFailed | ureq::Error::HostNotFound => true,
        ureq::Error::Timeout(t) => matches!(t, ureq::Timeout::Connect | ureq::Timeout::Resolve),
        ureq::Error::Io(io) => matches!(
            io.kind(),
            ErrorKind::ConnectionRefused
                | ErrorKind::AddrNotAvailable
                | ErrorKind::HostUnreachable
                | ErrorKind::NetworkUnreachable
        ),
        _ => false,
    }
}

/// Whether a request had no HTTP answer: the peer closed or reset the
/// connection without one, or answered in something else (a TLS alert),
/// as a server that speaks only https does to a plain request.
fn no_http_answer(e: &ureq::Error) -> bool {
    use std::io::ErrorKind;
    match e {
        ureq::Error::Io(io) => matches!(
            io.kind(),
            ErrorKind::UnexpectedEof | ErrorKind::ConnectionReset
        ),
        ureq::Error::Protocol(_) => true,
        _ => false,
    }
}

/// A connection to the server with a bearer token.
#[derive(Debug, Clone)]
pub struct Client {
    servers: std::sync::Arc<Servers>,
    auth: String,
    agent: ureq::Agent,
    notice: Notice,
    /// The longest a call waits out 429s and 503s in all.
    rate_wait: Duration,
}

/// Hears a line ([`Client::with_notice`]).
type Listener = dyn Fn(&str) + Send + Sync;

/// Who hears that a call waits out a 503 ([`Client::with_notice`]).
#[derive(Clone, Default)]
struct Notice(Option<std::sync::Arc<Listener>>);

impl std::fmt::Debug for Notice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Notice(set)"
        } else {
            "Notice(none)"
        })
    }
}

impl Client {
    /// A client of the server at `base` (such as `http://127.0.0.1:8080`)
    /// whose calls each take at most ten minutes.
    pub fn new(base: &str, token: &str) -> Self {
        Self::with_timeout(base, token, Duration::from_secs(600))
    }

    /// Whether a server has answered this client (or a clone of it).
    pub fn answered(&self) -> bool {
        self.servers
            .answered
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    /// A client whose calls each take at most `timeout`.
    pub fn with_timeout(base: &str, token: &str, timeout: Duration) -> Self {
        Self {
            servers: std::sync::Arc::new(Servers::new(vec![base.trim_end_matches('/').to_owned()])),
            auth: format!("Bearer {token}"),
            agent: agent(timeout),
            notice: Notice::default(),
            rate_wait: MAX_RATE_WAIT,
        }
    }

    /// This client (its servers, where it is among them, its token and
    /// notice) with calls that each take at most `timeout`.
    #[must_use]
    pub fn timed(&self, timeout: Duration) -> Self {
        Self {
            agent: agent(timeout),
            ..self.clone()
        }
    }

    /// This client, waiting out 429s and 503s for at most `wait` in all a
    /// call ([`MAX_RATE_WAIT`] unless set): zero answers them at once, as
    /// a process on its way out wants.
    #[must_use]
    pub fn with_rate_wait(mut self, wait: Duration) -> Self {
        self.rate_wait = wait;
        self
    }

    /// This client, telling `notice` when a call begins to wait out a 503
    /// (a line: what the server said and how long the call may wait), so
    /// that a wait through an outage is not taken for a hang.
    #[must_use]
    pub fn with_notice(mut self, notice: impl Fn(&str) + Send + Sync + 'static) -> Self {
        self.notice = Notice(Some(std::sync::Arc::new(notice)));
        self
    }

    /// This client, asking `others` too (servers of the same fleet: one
    /// database, one blob store) when the one it asks cannot be reached:
    /// a worker goes on through a server that is down without a load
    /// balancer. Clones share where they are.
    #[must_use]
    pub fn with_fallbacks(mut self, others: &[String]) -> Self {
        let mut urls = self.servers.urls.clone();
        urls.extend(others.iter().map(|u| u.trim_end_matches('/').to_owned()));
        self.servers = std::sync::Arc::new(Servers::new(urls));
        self
    }

    /// The URL of the server it asks now (without a trailing `/`).
    pub fn base(&self) -> String {
        self.servers.current().to_owned()
    }

    /// Whether `other` talks to the same servers with the same token.
    pub fn same_as(&self, other: &Self) -> bool {
        (&self.servers.urls, &self.auth) == (&other.servers.urls, &other.auth)
    }

    fn transport(&self, e: impl std::fmt::Display) -> ApiError {
        ApiError::Transport {
            base: self.base(),
            message: e.to_string(),
        }
    }

    fn decode(&self, e: impl std::fmt::Display) -> ApiError {
        ApiError::Decode {
            base: self.base(),
            message: e.to_string(),
        }
    }

    /// `request`'s response (it is given the server's URL), from the next
    /// servers of the fleet in turn when the one asked cannot be reached
    /// ([`never_arrived`]) or refused the handshake ([`tls_failure`]: no
    /// request went), each once; when none answers, the first error, or
    /// before any server has answered this client, the first failed
    /// handshake's ([`ApiError::Tls`]). Threads share where they are: the
    /// first to move on says so, the others follow it.
    fn reach(
        &self,
        request: &impl Fn(&str) -> std::result::Result<Response, ureq::Error>,
    ) -> Result<Response> {
        let urls = &self.servers.urls;
        let start = self.servers.index();
        let mark_answered = |res| {
            self.servers
                .answered
                .store(true, std::sync::atomic::Ordering::Relaxed);
            Ok(res)
        };
        let first = match request(&urls[start]) {
            Ok(res) => return mark_answered(res),
            Err(e) => e,
        };
        // The first failed handshake among the servers asked.
        let mut handshake = tls_failure(&first).map(|hint| (start, first.to_string(), hint));
        if never_arrived(&first) || handshake.is_some() {
            for k in 1..urls.len() {
                let i = (start + k) % urls.len();
                match request(&urls[i]) {
                    Ok(res) => {
                        let moved = self.servers.current.compare_exchange(
                            start,
                            i,
                            std::sync::atomic::Ordering::Relaxed,
                            std::sync::atomic::Ordering::Relaxed,
                        );
                        if let (Ok(_), Some(notice)) = (moved, &self.notice.0) {
                            let why = match &handshake {
                                Some((at, message, hint)) if *at == start => {
                                    format!("cannot be reached securely ({message}; {hint})")
                                }
                                _ => "cannot be reached".to_owned(),
                            };
                            notice(&format!("{} {why}: going on with {}", urls[start], urls[i]));
                        }
                        return mark_answered(res);
                    }
                    Err(e) => {
                        if handshake.is_none() {
                            handshake = tls_failure(&e).map(|hint| (i, e.to_string(), hint));
                        }
                    }
                }
            }
        }
        if let Some((i, message, hint)) = handshake
            && !self.answered()
        {
            return Err(ApiError::Tls {
                base: urls[i].clone(),
                message,
                hint,
            });
        }
        let base = &urls[start];
        let mut message = first.to_string();
        if let Some(address) = base.strip_prefix("http://")
            && no_http_answer(&first)
            && !self.answered()
        {
            message.push_str(&format!(
                " (no HTTP answer: if the server speaks https, its address is https://{address})"
            ));
        }
        Err(ApiError::Transport {
            base: base.clone(),
            message,
        })
    }

    /// Sends `request` until the server stops answering 429 (over its
    /// request rate) or 503 with a `Retry-After` (its database or blob
    /// store is not answering), waiting what each answer's `Retry-After`
    /// asks (1 to 30 s) and at most [`MAX_RATE_WAIT`] in all, then checks
    /// the status. A busy or recovering server slows a caller down; it
    /// does not fail it.
    fn send(
        &self,
        request: impl Fn(&str) -> std::result::Result<Response, ureq::Error>,
    ) -> Result<Response> {
        // Since the first request the server asked to come back later was
        // sent: the outage as this caller saw it, its own waits for
        // answers included.
        let mut began: Option<std::time::Instant> = None;
        let mut told = false;
        loop {
            let asked = std::time::Instant::now();
            let res = self.reach(&request)?;
            let come_back = match res.status().as_u16() {
                429 => true,
                503 => res.headers().contains_key("retry-after"),
                _ => false,
            };
            let waited = began.map_or(Duration::ZERO, |t| t.elapsed());
            if !come_back || waited >= self.rate_wait {
                // An outage it said it waits out is said to be over.
                if let Some(notice) = &self.notice.0
                    && told
                    && !come_back
                {
                    notice(&format!(
                        "{} answers again after {:.0} s",
                        self.base(),
                        waited.as_secs_f64()
                    ));
                }
                return self.check(res);
            }
            let unavailable = res.status().as_u16() == 503;
            let wait = Duration::from_secs(
                res.headers()
                    .get("retry-after")
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.trim().parse::<u64>().ok())
                    .unwrap_or(1)
                    .clamp(1, 30),
            );
            if let Some(notice) = &self.notice.0
                && unavailable
                && began.is_none()
            {
                let said = match self.check(res) {
                    Err(ApiError::Status { problem, .. }) => problem.detail,
                    _ => String::new(),
                };
                notice(&format!(
                    "{} answered 503 ({said}); asking again for up to {} s",
                    self.base(),
                    self.rate_wait.as_secs()
                ));
                told = true;
            }
            began.get_or_insert(asked);
            std::thread::sleep(wait);
        }
    }

    /// The answer when its status is a success, else its problem.
    fn check(&self, mut res: Response) -> Result<Response> {
        let status = res.status().as_u16();
        if status < 400 {
            return Ok(res);
        }
        let body = res.body_mut().read_to_string().unwrap_or_default();
        let problem = serde_json::from_str::<Problem>(&body).unwrap_or_else(|_| Problem {
            kind: "about:blank".to_owned(),
            title: res
                .status()
                .canonical_reason()
                .unwrap_or_default()
                .to_owned(),
            status,
            detail: gist(&body),
            code: String::new(),
            reason: None,
            pointer: None,
        });
        Err(ApiError::Status {
            status,
            problem: Box::new(problem),
        })
    }

    /// The answer's JSON body; a body cut off (the connection broke) is a
    /// transport error, worth another try, and only a whole body that is
    /// not the JSON asked for is [`ApiError::Decode`].
    fn read_json<R: DeserializeOwned>(&self, mut res: Response) -> Result<R> {
        res.body_mut()
            .with_config()
            .limit(1 << 30)
            .read_json()
            .map_err(|e| match &e {
                ureq::Error::Io(_) | ureq::Error::Timeout(_) => self.transport(e),
                // A body read as it streams (no length): its reads.
                ureq::Error::Json(j) if j.is_io() => self.transport(e),
                _ => self.decode(e),
            })
    }

    fn get<R: DeserializeOwned>(&self, path: &str) -> Result<R> {
        let res = self.send(|base| {
            self.agent
                .get(format!("{base}{path}"))
                .header("authorization", &self.auth)
                .call()
        })?;
        self.read_json(res)
    }

    /// Posts `body`; `None` when the server answers 204.
    fn post<T: Serialize, R: DeserializeOwned>(&self, path: &str, body: &T) -> Result<Option<R>> {
        let res = self.send(|base| {
            self.agent
                .post(format!("{base}{path}"))
                .header("authorization", &self.auth)
                .send_json(body)
        })?;
        if res.status().as_u16() == 204 {
            return Ok(None);
        }
        self.read_json(res).map(Some)
    }

    /// Posts `body` and reads the answer that the operation always has.
    fn post_for<T: Serialize, R: DeserializeOwned>(&self, path: &str, body: &T) -> Result<R> {
        self.post(path, body)?
            .ok_or_else(|| self.decode(format!("{path} answered 204, with no body")))
    }

    /// Posts `body` to an operation that answers 204.
    fn post_empty<T: Serialize>(&self, path: &str, body: &T) -> Result<()> {
        self.post::<_, serde::de::IgnoredAny>(path, body)?;
        Ok(())
    }

    /// Applies `action` (`cancel`, `pause`, `resume` or `retry`) to bake
    /// `id`; the bake's view after.
    pub fn control(&self, id: i64, action: &str) -> Result<BakeView> {
        let res = self.send(|base| {
            self.agent
                .post(format!("{base}/v1/bakes/{id}/{action}"))
                .header("authorization", &self.auth)
                .send_empty()
        })?;
        self.read_json(res)
    }

    /// The bytes at `path`, whatever their size.
    pub fn get_bytes(&self, path: &str) -> Result<Vec<u8>> {
        let mut res = self.send(|base| {
            self.agent
                .get(format!("{base}{path}"))
                .header("authorization", &self.auth)
                .call()
        })?;
        res.body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| self.transport(e))
    }

    fn upload(&self, path: &str, bytes: &[u8], bundle: bool, name: &str) -> Result<Uploaded> {
        let content_type = if bundle { BUNDLE } else { "model/gltf-binary" };
        let res = self.send(|base| {
            self.agent
                .post(format!("{base}{path}"))
                .query("name", name)
                .header("authorization", &self.auth)
                .header("content-type", content_type)
                .send(bytes)
        })?;
        self.read_json(res)
    }

    /// `POST /v1/characters`: a `.glb` (or a bundle of a `.gltf` and its
    /// side files) under the file name `name`.
    pub fn upload_character(&self, bytes: &[u8], bundle: bool, name: &str) -> Result<Uploaded> {
        self.upload("/v1/characters", bytes, bundle, name)
    }

    /// `POST /v1/clips` for the character with digest `character`.
    pub fn upload_clips(
        &self,
        character: &str,
        bytes: &[u8],
        bundle: bool,
        name: &str,
    ) -> Result<Uploaded> {
        self.upload(
            &format!("/v1/clips?character={character}"),
            bytes,
            bundle,
            name,
        )
    }

    /// `POST /v1/bakes`.
    pub fn submit(&self, request: &BakeRequest) -> Result<BakeView> {
        self.post_for("/v1/bakes", request)
    }

    /// `GET /v1/bakes/{id}`, with its jobs.
    pub fn bake(&self, id: i64) -> Result<BakeView> {
        self.get(&format!("/v1/bakes/{id}"))
    }

    /// `GET /v1/cache/{key}`: the finished bake with this key, or, when
    /// there is none, the server's word for why (none yet, or one under
    /// way).
    pub fn cached(&self, key: &str) -> Result<std::result::Result<BakeView, String>> {
        match self.get(&format!("/v1/cache/{key}")) {
            Err(ApiError::Status {
                status: 404,
                problem,
            }) => Ok(Err(problem.detail)),
            other => other.map(Ok),
        }
    }

    /// `GET /v1/bakes/{id}/report`, as JSON bytes (core's `BakeReport`).
    pub fn report(&self, id: i64) -> Result<Vec<u8>> {
        self.get_bytes(&format!("/v1/bakes/{id}/report"))
    }

    /// `GET /v1/bakes/{id}/previews`.
    pub fn previews(&self, id: i64) -> Result<crate::PreviewList> {
        self.get(&format!("/v1/bakes/{id}/previews"))
    }

    /// `GET /v1/assets/{digest}`: the published bytes.
    pub fn asset(&self, digest: &str) -> Result<Vec<u8>> {
        self.get_bytes(&format!("/v1/assets/{digest}"))
    }

    /// `GET /v1/whoami`.
    pub fn whoami(&self) -> Result<Whoami> {
        self.get("/v1/whoami")
    }

    /// `POST /v1/tokens` (admin).
    pub fn create_token(&self, request: &NewTokenRequest) -> Result<NewToken> {
        self.post_for("/v1/tokens", request)
    }

    /// `GET /v1/bakes`: the newest `limit` bakes (1 to 1000), of the
    /// method named `method` (such as `vertex-linear`) alone when given,
    /// newest first.
    pub fn bakes(&self, method: Option<&str>, limit: u32) -> Result<Vec<BakeView>> {
        self.get(&Self::bakes_path(method, limit))
    }

    /// The path [`Client::bakes`] asks.
    pub fn bakes_path(method: Option<&str>, limit: u32) -> String {
        let method = method.map_or_else(String::new, |m| format!("&method={m}"));
        format!("/v1/bakes?limit={limit}{method}")
    }

    /// `GET /v1/characters/{digest}`: a character upload's record (its
    /// file name and summary).
    pub fn character(&self, digest: &str) -> Result<crate::UploadRow> {
        self.get(&format!("/v1/characters/{digest}"))
    }

    /// `GET /v1/workers`: the workers the server knows, last seen first.
    pub fn workers(&self) -> Result<Vec<crate::WorkerRow>> {
        self.get("/v1/workers")
    }

    /// `GET /v1/tokens`: every token, newest first (needs `admin`).
    pub fn tokens(&self) -> Result<Vec<TokenView>> {
        self.get("/v1/tokens")
    }

    /// `DELETE /v1/tokens/{id}`: revokes a token (needs `admin`); it is
    /// refused from its next request on.
    pub fn revoke_token(&self, id: &str) -> Result<()> {
        self.send(|base| {
            self.agent
                .delete(format!("{base}/v1/tokens/{id}"))
                .header("authorization", &self.auth)
                .call()
        })?;
        Ok(())
    }

    /// Waits up to `wait_secs` for a job; `tracer` tells the server what
    /// casts the worker's rays (`cpu`, or `gpu: ` and the adapter): once
    /// is enough, it is recorded.
    pub fn lease(
        &self,
        worker: &str,
        wait_secs: u64,
        tracer: Option<&str>,
    ) -> Result<Option<Lease>> {
        self.post(
            "/v1/jobs/lease",
            &LeaseRequest {
                worker: worker.to_owned(),
                wait_secs,
                tracer: tracer.map(str::to_owned),
                request: None,
            },
        )
    }

    /// Waits up to `wait_secs` for jobs for a process's idle slots
    /// `workers` (1 to 64 ids): at most one each, in that order, none
    /// when no job came in time. `request` is the request's nonce, sent
    /// again unchanged when no answer came (`LeaseManyRequest::request`).
    pub fn lease_many(
        &self,
        workers: &[String],
        wait_secs: u64,
        tracer: Option<&str>,
        request: Option<&str>,
    ) -> Result<Vec<Lease>> {
        let leases: Option<Leases> = self.post(
            "/v1/jobs/leases",
            &LeaseManyRequest {
                workers: workers.to_vec(),
                wait_secs,
                tracer: tracer.map(str::to_owned),
                request: request.map(str::to_owned),
            },
        )?;
        Ok(leases.map(|l| l.leases).unwrap_or_default())
    }

    /// Completes several jobs (1 to 64) in one request: one outcome per
    /// item, in order, a refused one with the status and problem that
    /// `complete` would have got.
    pub fn complete_many(&self, items: &[JobCompletion]) -> Result<Vec<Result<()>>> {
        let reply: CompleteManyReply = self.post_for(
            "/v1/jobs/completions",
            &CompleteManyRequest {
                completions: items.to_vec(),
            },
        )?;
        Ok(reply
            .results
            .into_iter()
            .map(|r| match r.problem {
                None => Ok(()),
                Some(problem) => Err(ApiError::Status {
                    status: problem.status,
                    problem: Box::new(problem),
                }),
            })
            .collect())
    }

    /// Extends the lease; `true` asks the job to stop.
    pub fn heartbeat(&self, job: i64, token: &str, progress: u64) -> Result<HeartbeatReply> {
        self.post_for(
            &format!("/v1/jobs/{job}/heartbeat"),
            &HeartbeatRequest {
                token: token.to_owned(),
                progress: i64::try_from(progress).unwrap_or(i64::MAX),
            },
        )
    }

    /// Records a checkpoint whose blob is stored.
    pub fn checkpoint(&self, job: i64, token: &str, checkpoint: &CheckpointRef) -> Result<()> {
        self.post_empty(
            &format!("/v1/jobs/{job}/checkpoint"),
            &CheckpointRequest {
                token: token.to_owned(),
                checkpoint: checkpoint.clone(),
            },
        )
    }

    /// Completes the job.
    pub fn complete(&self, job: i64, token: &str, completion: Completion) -> Result<()> {
        self.post_empty(
            &format!("/v1/jobs/{job}/complete"),
            &CompleteRequest {
                token: token.to_owned(),
                completion,
            },
        )
    }

    /// Fails this attempt.
    pub fn fail(&self, job: i64, token: &str, error: &str, retryable: bool) -> Result<()> {
        self.post_empty(
            &format!("/v1/jobs/{job}/fail"),
            &FailRequest {
                token: token.to_owned(),
                error: error.to_owned(),
                retryable,
            },
        )
    }

    /// Gives the lease back without using up an attempt.
    pub fn release(&self, job: i64, token: &str) -> Result<()> {
        self.post_empty(
            &format!("/v1/jobs/{job}/release"),
            &TokenRequest {
                token: token.to_owned(),
            },
        )
    }

    /// The bake key the server gives `request` (its `priority` aside),
    /// without uploading or baking.
    pub fn key(&self, request: &BakeRequest) -> Result<BakeKey> {
        self.post_for("/v1/keys", request)
    }

    /// Tells the server that these worker ids (a process's slots) have
    /// stopped: `GET /v1/workers` lists them as stopped at once instead of
    /// a lease after they were last seen.
    pub fn workers_stopped(&self, workers: &[String]) -> Result<()> {
        self.post_empty(
            "/v1/workers/stopped",
            &WorkersStopped {
                workers: workers.to_vec(),
            },
        )
    }

    /// A blob's bytes.
    pub fn get_blob(&self, digest: &str) -> Result<Vec<u8>> {
        self.get_bytes(&format!("/v1/blobs/{digest}"))
    }

    /// Stores a blob; returns its digest (sha256, lower-case hex).
    pub fn put_blob(&self, bytes: &[u8]) -> Result<String> {
        let digest: String = Sha256::digest(bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        self.send(|base| {
            self.agent
                .put(format!("{base}/v1/blobs/{digest}"))
                .header("authorization", &self.auth)
                .send(bytes)
        })?;
        Ok(digest)
    }
}

/// A body that is not a problem (an HTML error page of a proxy or of
/// another server) as one short line: its words, at most 200 characters.
fn gist(body: &str) -> String {
    let words = body.split_whitespace().collect::<Vec<_>>().join(" ");
    match words.char_indices().nth(200) {
        Some((at, _)) => format!("{}… ({} bytes)", &words[..at], body.len()),
        None => words,
    }
}

#[cfg(test)]
mod tests {
    use std::io::{BufRead as _, BufReader, Write as _};

    use super::*;

    fn unreachable() -> ApiError {
        ApiError::Transport {
            base: "http://127.0.0.1:1".into(),
            message: "Connection refused".into(),
        }
    }

    fn answered(status: u16) -> ApiError {
        ApiError::Status {
            status,
            problem: Box::new(Problem {
                kind: "about:blank".into(),
                title: "t".into(),
                status,
                detail: "d".into(),
                code: "c".into(),
                reason: None,
                pointer: None,
            }),
        }
    }

    /// `retry` with a short first wait, always keeping on, counting the
    /// calls and the waits it was told of.
    fn tries(
        window: Duration,
        mut answer: impl FnMut(usize) -> Result<usize>,
    ) -> (Result<usize>, usize, usize) {
        let (mut calls, mut waits) = (0, 0);
        let got = retry(
            window,
            Duration::from_millis(2),
            || true,
            |_, _| waits += 1,
            || {
                calls += 1;
                answer(calls)
            },
        );
        (got, calls, waits)
    }

    /// A server away for longer than a few quick tries (6 refusals, and a
    /// 503 and a 502 between) is waited for within the window.
    #[test]
    fn an_outage_is_waited_out_within_the_window() {
        let (got, calls, waits) = tries(Duration::from_secs(10), |n| match n {
            1..=4 => Err(unreachable()),
            5 => Err(answered(503)),
            6 => Err(answered(502)),
            _ => Ok(n),
        });
        assert_eq!((got.unwrap(), calls, waits), (7, 7, 6));
    }

    /// Past the window an outage's last error comes back; a 500 (a fault
    /// that tends to repeat) is tried three times in all; a 409 (the lease
    /// is gone) or a 4xx ends the tries at once.
    #[test]
    fn tries_end_with_the_window_a_repeated_fault_or_a_lasting_answer() {
        let started = std::time::Instant::now();
        let (got, calls, _) = tries(Duration::from_secs(1), |_| Err(unreachable()));
        assert!(got.unwrap_err().is_outage());
        assert!(calls >= 3, "{calls}");
        assert!(
            started.elapsed() < Duration::from_secs(5),
            "{:?}",
            started.elapsed()
        );
        let (got, calls, waits) = tries(Duration::from_secs(60), |_| Err(answered(500)));
        assert_eq!((got.unwrap_err().status(), calls, waits), (Some(500), 3, 2));
        for status in [409, 404] {
            let (got, calls, _) = tries(Duration::from_secs(60), |_| Err(answered(status)));
            assert_eq!((got.unwrap_err().status(), calls), (Some(status), 1));
        }
    }

    /// `keep_on` saying no (a worker past its shutdown deadline) ends an
    /// outage's tries.
    #[test]
    fn tries_end_when_told_to_stop() {
        let mut asked = 0;
        let got: Result<()> = retry(
            Duration::from_secs(60),
            Duration::from_millis(1),
            || {
                asked += 1;
                asked < 3
            },
            |_, _| {},
            || Err(unreachable()),
        );
        assert!(got.is_err());
        assert_eq!(asked, 3);
    }

    /// A server on a free port that answers its connections, one request
    /// each, with `answers` in turn; returns its address.
    fn serve(answers: Vec<&'static str>) -> String {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        std::thread::spawn(move || {
            for answer in answers {
                let (mut stream, _) = listener.accept().unwrap();
                let mut reader = BufReader::new(stream.try_clone().unwrap());
                let mut line = String::new();
                while reader.read_line(&mut line).unwrap() > 0 && line != "\r\n" {
                    line.clear();
                }
                stream.write_all(answer.as_bytes()).unwrap();
            }
        });
        format!("http://{addr}")
    }

    /// Threads that find their server gone go on with the next of the
    /// fleet, and it is said once; a request that reached a server which
    /// then failed to answer is not sent to another (it may have been
    /// done).
    #[test]
    fn a_client_goes_on_with_the_next_server_only_when_none_was_reached() {
        let ok = "HTTP/1.1 200 OK\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc";
        let live = serve(vec![ok; 4]);
        let heard = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
        let into = heard.clone();
        let client = Client::new("http://127.0.0.1:1", "t")
            .with_fallbacks(std::slice::from_ref(&live))
            .with_notice(move |line| into.lock().unwrap().push(line.to_owned()));
        std::thread::scope(|scope| {
            for _ in 0..4 {
                let client = client.clone();
                scope.spawn(move || assert_eq!(client.get_blob("d").unwrap(), b"abc"));
            }
        });
        assert_eq!(client.base(), live);
        let heard = heard.lock().unwrap();
        assert_eq!(
            *heard,
            [format!(
                "http://127.0.0.1:1 cannot be reached: going on with {live}"
            )]
        );
        // A server that took the request and closed without an answer.
        let mute = serve(vec!["", ""]);
        let other = serve(vec![ok]);
        let client = Client::new(&mute, "t").with_fallbacks(std::slice::from_ref(&other));
        assert!(matches!(
            client.get_blob("d"),
            Err(ApiError::Transport { base, .. }) if base == mute
        ));
        assert_eq!(client.base(), mute);
    }

    #[test]
    fn a_rate_limited_call_waits_and_is_sent_again() {
        let base = serve(vec![
            "HTTP/1.1 429 Too Many Requests\r\nRetry-After: 1\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            "HTTP/1.1 200 OK\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc",
        ]);
        let started = std::time::Instant::now();
        let bytes = Client::new(&base, "t").get_blob("d").unwrap();
        assert_eq!(bytes, b"abc");
        assert!(started.elapsed() >= Duration::from_secs(1), "it waited");
        // A 503 that says when to come back is waited out too, and the
        // client's notice hears of it once, with what the server said.
        let base = serve(vec![
            "HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Length: 33\r\nConnection: close\r\n\r\nthe blob store is not answering\r\n",
            "HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            "HTTP/1.1 200 OK\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc",
        ]);
        let heard = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
        let into = heard.clone();
        let client = Client::new(&base, "t").with_notice(move |line| {
            into.lock().unwrap().push(line.to_owned());
        });
        let started = std::time::Instant::now();
        assert_eq!(client.get_blob("d").unwrap(), b"abc");
        assert!(started.elapsed() >= Duration::from_secs(2), "it waited");
        let heard = heard.lock().unwrap();
        assert_eq!(heard.len(), 2, "{heard:?}");
        assert!(
            heard[0].contains("answered 503 (the blob store is not answering)")
                && heard[0].contains("asking again for up to 300 s"),
            "{heard:?}"
        );
        assert!(heard[1].ends_with("answers again after 2 s"), "{heard:?}");
        // Other failures are not retried.
        let base = serve(vec![
            "HTTP/1.1 503 Service Unavailable\r\nContent-Length: 4\r\nConnection: close\r\n\r\ndown",
        ]);
        match Client::new(&base, "t").get_blob("d") {
            Err(e @ ApiError::Status { status: 503, .. }) => {
                assert!(e.is_transient());
                let ApiError::Status { problem, .. } = e else {
                    unreachable!()
                };
                assert_eq!(problem.detail, "down");
            }
            other => panic!("{other:?}"),
        }
        // Another server's error page is told in one short line.
        let page = format!(
            "<html>\n<body>\n{}</body></html>",
            "<p>Internal error</p>\n".repeat(40)
        );
        let answer = Box::leak(
            format!(
                "HTTP/1.1 500 Internal Server Error\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{page}",
                page.len()
            )
            .into_boxed_str(),
        );
        let base = serve(vec![answer]);
        let Err(ApiError::Status { problem, .. }) = Client::new(&base, "t").get_blob("d") else {
            panic!("a 500")
        };
        assert!(
            !problem.detail.contains('\n')
                && problem
                    .detail
                    .starts_with("<html> <body> <p>Internal error</p>")
                && problem
                    .detail
                    .ends_with(&format!("… ({} bytes)", page.len())),
            "{}",
            problem.detail
        );
    }

    /// An HTTP/1.1 answer with a JSON body.
    fn answer(status: &str, body: &str) -> &'static str {
        Box::leak(
            format!(
                "HTTP/1.1 {status}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                body.len()
            )
            .into_boxed_str(),
        )
    }

    #[test]
    fn an_error_status_carries_the_servers_problem() {
        let base = serve(vec![answer(
            "409 Conflict",
            r#"{"type":"about:blank","title":"Conflict","status":409,"detail":"job 3 is not leased with this token","code":"lease_lost"}"#,
        )]);
        let err = Client::new(&base, "t").release(3, "x").unwrap_err();
        assert!(err.is_lease_lost(), "{err:?}");
        assert!(!err.is_transient());
        let ApiError::Status { problem, .. } = &err else {
            panic!("{err:?}")
        };
        assert_eq!(problem.code, "lease_lost");
        assert_eq!(
            err.to_string(),
            "the server answered 409: job 3 is not leased with this token"
        );
    }

    #[test]
    fn a_typed_answer_is_decoded_and_a_wrong_one_is_an_error() {
        let base = serve(vec![
            answer("200 OK", r#"{"name":"ci","scopes":["read","submit"]}"#),
            answer("200 OK", "[]"),
        ]);
        let client = Client::new(&base, "t");
        let me = client.whoami().unwrap();
        assert_eq!((me.name.as_str(), me.scopes.len()), ("ci", 2));
        assert!(matches!(client.whoami(), Err(ApiError::Decode { .. })));
    }

    /// A handshake that met a certificate no CA here signed, as rustls
    /// reports it through ureq.
    fn untrusted() -> ureq::Error {
        ureq::Error::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            rustls::Error::InvalidCertificate(rustls::CertificateError::UnknownIssuer),
        ))
    }

    /// A 200 answer.
    fn ok() -> std::result::Result<Response, ureq::Error> {
        Ok(ureq::http::Response::builder()
            .status(200)
            .body(ureq::Body::builder().data("ok"))
            .unwrap())
    }

    /// A failed handshake is a setup problem (`Tls`, saying what to do)
    /// until a server has answered the client; after that, an outage to
    /// wait out (a proxy serving a placeholder certificate as it starts).
    #[test]
    fn a_failed_handshake_is_final_only_before_the_first_answer() {
        let client = Client::new("https://127.0.0.1:1", "t");
        match client.reach(&|_| Err(untrusted())) {
            Err(ApiError::Tls { hint, .. }) => {
                assert!(hint.contains("not one this machine trusts"), "{hint}");
            }
            other => panic!("{other:?}"),
        }
        let answered = client.reach(&|_| ok());
        assert!(answered.is_ok());
        let later = client.reach(&|_| Err(untrusted())).unwrap_err();
        assert!(
            matches!(later, ApiError::Transport { .. }) && later.is_outage(),
            "{later:?}"
        );
    }

    /// A fleet's next server is asked after a failed handshake (no request
    /// went), saying why; when none answers, a failed handshake anywhere
    /// is the error, not the first server's refused connection.
    #[test]
    fn a_fleet_goes_on_past_a_failed_handshake_and_names_it() {
        let heard = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
        let into = heard.clone();
        let client = Client::new("https://a", "t")
            .with_fallbacks(&["https://b".to_owned()])
            .with_notice(move |line| into.lock().unwrap().push(line.to_owned()));
        let answer = client.reach(&|url| {
            if url == "https://a" {
                Err(untrusted())
            } else {
                ok()
            }
        });
        assert!(answer.is_ok());
        let heard = heard.lock().unwrap();
        assert!(
            heard.len() == 1
                && heard[0].starts_with("https://a cannot be reached securely")
                && heard[0].contains("not one this machine trusts")
                && heard[0].ends_with("going on with https://b"),
            "{heard:?}"
        );
        let fleet = Client::new("https://a", "t").with_fallbacks(&["https://b".to_owned()]);
        let refused = fleet.reach(&|url| {
            if url == "https://a" {
                Err(ureq::Error::ConnectionFailed)
            } else {
                Err(untrusted())
            }
        });
        assert!(
            matches!(&refused, Err(ApiError::Tls { base, .. }) if base == "https://b"),
            "{refused:?}"
        );
    }

    /// Each failed handshake says what to do about its cause.
    #[test]
    fn a_failed_handshake_says_what_to_do_about_its_cause() {
        let io = |e: rustls::Error| {
            ureq::Error::Io(std::io::Error::new(std::io::ErrorKind::InvalidData, e))
        };
        let ca_as_leaf = rustls::Error::InvalidCertificate(rustls::CertificateError::Other(
            rustls::OtherError(std::sync::Arc::new(webpki::Error::CaUsedAsEndEntity)),
        ));
        for (e, says) in [
            (io(ca_as_leaf), "presents a CA's certificate as its own"),
            (
                io(rustls::Error::InvalidCertificate(
                    rustls::CertificateError::UnknownIssuer,
                )),
                "not one this machine trusts",
            ),
            (
                ureq::Error::Rustls(rustls::Error::General("No CA certificates".into())),
                "trust store is empty",
            ),
            (
                io(rustls::Error::InvalidCertificate(
                    rustls::CertificateError::NotValidForName,
                )),
                "does not name the host of this address",
            ),
            (
                io(rustls::Error::InvalidCertificate(
                    rustls::CertificateError::Expired,
                )),
                "has expired",
            ),
        ] {
            let hint = tls_failure(&e).unwrap_or_else(|| panic!("{e}: not a TLS failure"));
            assert!(hint.contains(says), "{e}: {hint}");
        }
        assert_eq!(tls_failure(&ureq::Error::ConnectionFailed), None);
    }

    /// `https://` to a server that speaks plain HTTP says so.
    #[test]
    fn https_to_a_plain_http_server_says_it_does_not_answer_in_tls() {
        use std::io::Read as _;
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        std::thread::spawn(move || {
            let (mut stream, _) = listener.accept().unwrap();
            let _ = stream.read(&mut [0u8; 4096]);
            let _ = stream.write_all(
                b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
            );
        });
        match Client::new(&format!("https://{addr}"), "t").whoami() {
            Err(e @ ApiError::Tls { hint, .. }) => {
                assert!(hint.contains("is it an http:// address"), "{e}");
            }
            other => panic!("{other:?}"),
        }
    }
}
