//! The server's job API as blocking calls (ureq): a worker's threads each
//! wait on one request at a time, so no async runtime is needed.

use std::time::Duration;

use serde::{Deserialize, Serialize, de::DeserializeOwned};

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

    fn check(
        &self,
        res: Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    ) -> Result<ureq::http::Response<ureq::Body>, ClientError> {
        let mut res = res.map_err(|e| ClientError::Transport(e.to_string()))?;
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
        let res = self.check(
            self.agent
                .post(format!("{}{path}", self.base))
                .header("authorization", &self.auth)
                .send_json(body),
        )?;
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
        let mut res = self.check(
            self.agent
                .get(format!("{}/v1/blobs/{digest}", self.base))
                .header("authorization", &self.auth)
                .call(),
        )?;
        res.body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| ClientError::Transport(e.to_string()))
    }

    /// Stores a blob; returns its digest.
    pub fn put_blob(&self, bytes: &[u8]) -> Result<String, ClientError> {
        let digest = aobake_core::digest::sha256_hex(bytes);
        self.check(
            self.agent
                .put(format!("{}/v1/blobs/{digest}", self.base))
                .header("authorization", &self.auth)
                .send(bytes),
        )?;
        Ok(digest)
    }
}
