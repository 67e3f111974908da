//! The server's job API as blocking calls (ureq): a worker's threads each
//! wait on one request at a time, so no async runtime is needed.

use std::time::Duration;

use serde::{Deserialize, Serialize, de::DeserializeOwned};

/// The longest a call waits in all on a server that answers 429 before it
/// fails with that status.
const MAX_RATE_WAIT: Duration = Duration::from_secs(300);

/// A failed call.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// 409: the lease is gone (expired and re-leased, or cancelled).
    #[error("the lease was lost: {0}")]
    LeaseLost(String),
    /// Any other status.
    #[error("{status}: {body}")]
    Status {
        /// HTTP status.
        status: u16,
        /// The problem+json body.
        body: String,
    },
    /// The server could not be reached.
    #[error("transport: {0}")]
    Transport(String),
}

/// A connection to the server with a bearer token.
#[derive(Debug, Clone)]
pub struct Client {
    base: String,
    auth: String,
    agent: ureq::Agent,
}

/// An output blob of a dependency.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OutputRef {
    /// Output name.
    pub name: String,
    /// Blob digest.
    pub digest: String,
}

/// A dependency's outputs and stage seconds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DepOutputs {
    /// Outputs.
    pub outputs: Vec<OutputRef>,
    /// Stage seconds (core's `Timings`).
    pub timings: serde_json::Value,
}

/// A saved checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointRef {
    /// Step.
    pub step: String,
    /// Cursor.
    pub cursor: i64,
    /// Blob digest.
    pub blob: String,
}

/// The leased job.
#[derive(Debug, Clone, Deserialize)]
pub struct LeasedJob {
    /// Job id.
    pub id: i64,
    /// Bake id.
    pub bake_id: i64,
    /// Core's `JobSpec`.
    pub spec: serde_json::Value,
    /// Units of work.
    pub work: i64,
    /// This lease's attempt number.
    pub attempts: i64,
    /// The last checkpoint.
    pub checkpoint: Option<CheckpointRef>,
}

/// The bake the job belongs to.
#[derive(Debug, Clone, Deserialize)]
pub struct LeasedBake {
    /// Bake id.
    pub id: i64,
    /// Fully defaulted parameters (core's `BakeParams`).
    pub params: serde_json::Value,
}

/// An upload the job reads.
#[derive(Debug, Clone, Deserialize)]
pub struct UploadRef {
    /// Blob digest.
    pub digest: String,
    /// Whether it is a bundle.
    pub bundle: bool,
}

/// `POST /v1/jobs/lease`'s answer.
#[derive(Debug, Clone, Deserialize)]
pub struct Lease {
    /// The job.
    pub job: LeasedJob,
    /// Its lease token.
    pub token: String,
    /// Its bake.
    pub bake: LeasedBake,
    /// Outputs of its dependencies.
    pub inputs: Vec<DepOutputs>,
    /// The character's upload, then the clips'.
    pub uploads: Vec<UploadRef>,
}

impl Client {
    /// A client of the server at `base` (such as `http://127.0.0.1:8080`).
    pub fn new(base: &str, token: &str) -> Self {
        let agent = ureq::Agent::config_builder()
            .timeout_global(Some(Duration::from_secs(120)))
            .http_status_as_error(false)
            .build()
            .into();
        Self {
            base: base.trim_end_matches('/').to_owned(),
            auth: format!("Bearer {token}"),
            agent,
        }
    }

    /// Sends `request` until the server stops answering 429 (over its
    /// request rate), waiting what each answer's `Retry-After` asks (1 to
    /// 30 s) and at most [`MAX_RATE_WAIT`] in all, then checks the status.
    /// A busy server slows a job down; it does not fail it.
    fn send(
        &self,
        request: impl Fn() -> Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    ) -> Result<ureq::http::Response<ureq::Body>, ClientError> {
        let mut waited = Duration::ZERO;
        loop {
            let res = request().map_err(|e| ClientError::Transport(e.to_string()))?;
            if res.status().as_u16() != 429 || waited >= MAX_RATE_WAIT {
                return self.check(res);
            }
            let wait = Duration::from_secs(
                res.headers()
                    .get("retry-after")
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.trim().parse::<u64>().ok())
                    .unwrap_or(1)
                    .clamp(1, 30),
            );
            std::thread::sleep(wait);
            waited += wait;
        }
    }

    fn check(
        &self,
        mut res: ureq::http::Response<ureq::Body>,
    ) -> Result<ureq::http::Response<ureq::Body>, ClientError> {
        let status = res.status().as_u16();
        if status < 300 {
            return Ok(res);
        }
        let body = res.body_mut().read_to_string().unwrap_or_default();
        if status == 409 {
            return Err(ClientError::LeaseLost(body));
        }
        Err(ClientError::Status { status, body })
    }

    fn post<T: Serialize, R: DeserializeOwned>(
        &self,
        path: &str,
        body: &T,
    ) -> Result<Option<R>, ClientError> {
        let res = self.send(|| {
            self.agent
                .post(format!("{}{path}", self.base))
                .header("authorization", &self.auth)
                .send_json(body)
        })?;
        if res.status().as_u16() == 204 {
            return Ok(None);
        }
        let mut res = res;
        res.body_mut()
            .read_json()
            .map(Some)
            .map_err(|e| ClientError::Transport(e.to_string()))
    }

    /// Waits up to `wait_secs` for a job.
    pub fn lease(&self, worker: &str, wait_secs: u64) -> Result<Option<Lease>, ClientError> {
        self.post(
            "/v1/jobs/lease",
            &serde_json::json!({"worker": worker, "wait_secs": wait_secs}),
        )
    }

    /// Extends the lease; `true` asks the job to stop.
    pub fn heartbeat(&self, job: i64, token: &str, progress: u64) -> Result<bool, ClientError> {
        let r: Option<serde_json::Value> = self.post(
            &format!("/v1/jobs/{job}/heartbeat"),
            &serde_json::json!({"token": token, "progress": progress}),
        )?;
        Ok(r.and_then(|v| v["stop"].as_bool()).unwrap_or(false))
    }

    /// Records a checkpoint whose blob is stored.
    pub fn checkpoint(
        &self,
        job: i64,
        token: &str,
        checkpoint: &CheckpointRef,
    ) -> Result<(), ClientError> {
        let mut body = serde_json::to_value(checkpoint).expect("serialises");
        body["token"] = token.into();
        self.post::<_, serde_json::Value>(&format!("/v1/jobs/{job}/checkpoint"), &body)?;
        Ok(())
    }

    /// Completes the job.
    pub fn complete(
        &self,
        job: i64,
        token: &str,
        outputs: &[OutputRef],
        timings: &serde_json::Value,
    ) -> Result<(), ClientError> {
        self.post::<_, serde_json::Value>(
            &format!("/v1/jobs/{job}/complete"),
            &serde_json::json!({"token": token, "outputs": outputs, "timings": timings}),
        )?;
        Ok(())
    }

    /// Fails this attempt.
    pub fn fail(
        &self,
        job: i64,
        token: &str,
        error: &str,
        retryable: bool,
    ) -> Result<(), ClientError> {
        self.post::<_, serde_json::Value>(
            &format!("/v1/jobs/{job}/fail"),
            &serde_json::json!({"token": token, "error": error, "retryable": retryable}),
        )?;
        Ok(())
    }

    /// Gives the lease back without using up an attempt.
    pub fn release(&self, job: i64, token: &str) -> Result<(), ClientError> {
        self.post::<_, serde_json::Value>(
            &format!("/v1/jobs/{job}/release"),
            &serde_json::json!({"token": token}),
        )?;
        Ok(())
    }

    /// A blob's bytes.
    pub fn get_blob(&self, digest: &str) -> Result<Vec<u8>, ClientError> {
        let mut res = self.send(|| {
            self.agent
                .get(format!("{}/v1/blobs/{digest}", self.base))
                .header("authorization", &self.auth)
                .call()
        })?;
        res.body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| ClientError::Transport(e.to_string()))
    }

    /// Stores a blob; returns its digest.
    pub fn put_blob(&self, bytes: &[u8]) -> Result<String, ClientError> {
        let digest = aobake_core::digest::sha256_hex(bytes);
        self.send(|| {
            self.agent
                .put(format!("{}/v1/blobs/{digest}", self.base))
                .header("authorization", &self.auth)
                .send(bytes)
        })?;
        Ok(digest)
    }
}

#[cfg(test)]
mod tests {
    use std::io::{BufRead as _, BufReader, Write as _};

    use super::*;

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
        // Other failures are not retried.
        let base = serve(vec![
            "HTTP/1.1 503 Service Unavailable\r\nContent-Length: 4\r\nConnection: close\r\n\r\ndown",
        ]);
        match Client::new(&base, "t").get_blob("d") {
            Err(ClientError::Status { status: 503, body }) => assert_eq!(body, "down"),
            other => panic!("{other:?}"),
        }
    }
}
