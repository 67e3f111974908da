//! A wrong or missing token gets 401, a token without the scope (or one
//! that includes it: `admin` all, `submit` `read`) 403, on every route (the health probes excepted: load balancers call them
//! without a token).

use aobake_e2e::{Options, TestEnv};
use serde_json::json;

/// Any valid token, whatever its scopes.
const ANY: &str = "any";

/// Every authenticated operation of the API and the scope it needs.
const ROUTES: &[(&str, &str, &str)] = &[
    ("POST", "/v1/characters", "submit"),
    ("GET", "/v1/characters/{digest}", "read"),
    ("GET", "/v1/characters/{digest}/bakes", "read"),
    ("POST", "/v1/clips", "submit"),
    ("GET", "/v1/clips/{digest}", "read"),
    ("POST", "/v1/bakes", "submit"),
    ("GET", "/v1/bakes", "read"),
    ("GET", "/v1/bakes/{id}", "read"),
    ("PATCH", "/v1/bakes/{id}", "submit"),
    ("GET", "/v1/bakes/{id}/report", "read"),
    ("GET", "/v1/bakes/{id}/events", "read"),
    ("GET", "/v1/bakes/{id}/previews", "read"),
    // The viewer's bundles carry the character's mesh: the studio's source.
    ("GET", "/v1/bakes/{id}/viewer", "submit"),
    ("GET", "/v1/bakes/{id}/viewer/frames", "submit"),
    ("GET", "/v1/events", "read"),
    ("GET", "/v1/previews/{digest}", "read"),
    ("HEAD", "/v1/previews/{digest}", "read"),
    ("GET", "/v1/whoami", ANY),
    ("POST", "/v1/bakes/{id}/{action}", "submit"),
    ("GET", "/v1/cache/{key}", "read"),
    ("GET", "/v1/assets/{digest}", "read"),
    ("HEAD", "/v1/assets/{digest}", "read"),
    ("POST", "/v1/jobs/lease", "worker"),
    ("POST", "/v1/jobs/leases", "worker"),
    ("POST", "/v1/jobs/completions", "worker"),
    ("POST", "/v1/jobs/{id}/heartbeat", "worker"),
    ("POST", "/v1/jobs/{id}/checkpoint", "worker"),
    ("POST", "/v1/jobs/{id}/complete", "worker"),
    ("POST", "/v1/jobs/{id}/fail", "worker"),
    ("POST", "/v1/jobs/{id}/release", "worker"),
    ("POST", "/v1/workers/stopped", "worker"),
    ("GET", "/v1/blobs/{digest}", "worker"),
    ("PUT", "/v1/blobs/{digest}", "worker"),
    ("GET", "/v1/workers", "read"),
    ("POST", "/v1/keys", "read"),
    ("POST", "/v1/tokens", "admin"),
    ("GET", "/v1/tokens", "admin"),
    ("DELETE", "/v1/tokens/{id}", "admin"),
    ("GET", "/metrics", "read"),
];

/// Unauthenticated on purpose: load balancers probe them.
const PUBLIC: &[(&str, &str)] = &[
    ("GET", "/healthz"),
    ("GET", "/readyz"),
    ("GET", "/v1/openapi.yaml"),
];

/// Concrete paths for a route template (every action of `{action}`).
fn concrete(template: &str) -> Vec<String> {
    let d = "a".repeat(64);
    let p = template
        .replace("{digest}", &d)
        .replace("{key}", &d)
        .replace("{id}", "1");
    let p = match p.as_str() {
        "/v1/clips" => format!("/v1/clips?character={d}"),
        "/v1/bakes/1/viewer/frames" => format!("{p}?clip=walk"),
        _ => p,
    };
    if p.contains("{action}") {
        ["cancel", "pause", "resume", "retry"]
            .iter()
            .map(|a| p.replace("{action}", a))
            .collect()
    } else {
        vec![p]
    }
}

/// The operations `api-spec/openapi.yaml` lists (method, path).
fn spec_operations() -> Vec<(String, String)> {
    let spec = std::fs::read_to_string(aobake_e2e::repo().join("api-spec/openapi.yaml")).unwrap();
    let mut out = Vec::new();
    let mut in_paths = false;
    let mut path = String::new();
    for line in spec.lines() {
        if !line.starts_with(' ') {
            in_paths = line == "paths:";
            continue;
        }
        if !in_paths {
            continue;
        }
        if let Some(p) = line.strip_prefix("  /") {
            path = format!("/{}", p.trim_end_matches(':'));
        } else if let Some(m) = line.strip_prefix("    ")
            && !m.starts_with(' ')
            && ["get:", "head:", "post:", "put:", "patch:", "delete:"].contains(&m)
        {
            out.push((m.trim_end_matches(':').to_uppercase(), path.clone()));
        }
    }
    out
}

#[test]
fn the_table_covers_every_operation_of_the_spec() {
    let mut spec = spec_operations();
    spec.sort();
    let mut table: Vec<(String, String)> = ROUTES
        .iter()
        .map(|(m, p, _)| (m.to_string(), p.to_string()))
        .chain(PUBLIC.iter().map(|(m, p)| (m.to_string(), p.to_string())))
        .collect();
    table.sort();
    assert_eq!(spec, table);
}

#[test]
fn every_route_refuses_missing_wrong_and_unscoped_tokens() {
    let env = TestEnv::start(Options::default());
    let tokens: Vec<(&str, String)> = ["read", "submit", "worker"]
        .into_iter()
        .map(|s| (s, env.token(&[s])))
        .collect();
    for (method, template, scope) in ROUTES.iter().copied() {
        // A HEAD request has no body, and its answer none either: its
        // status says it all.
        let head = method == "HEAD";
        let body = (!head).then(|| json!({}));
        for path in concrete(template) {
            for (token, what) in [("", "no token"), ("not-a-token", "a wrong token")] {
                let (status, answer) = env.request(method, &path, token, body.clone()).unwrap();
                assert_eq!(status, 401, "{method} {path} with {what}: {answer}");
                assert!(head || answer["code"] == "unauthorized", "{answer}");
            }
            for (s, token) in &tokens {
                // `submit` includes `read`: a build system follows and
                // fetches the bakes it submits.
                if *s == scope || scope == ANY || (*s == "submit" && scope == "read") {
                    // The status alone: an event stream never ends.
                    let status = status_only(&env, method, &path, token);
                    assert!(
                        status != 401 && status != 403,
                        "{method} {path} refused a {s} token: {status}"
                    );
                } else {
                    let (status, answer) = env.request(method, &path, token, body.clone()).unwrap();
                    assert_eq!(status, 403, "{method} {path} with a {s} token: {answer}");
                    assert!(head || answer["code"] == "forbidden", "{answer}");
                }
            }
        }
    }
    for (method, probe) in PUBLIC {
        assert_eq!(env.request(method, probe, "", None).unwrap().0, 200);
    }
    // The spec a client generator fetches is the committed one.
    let served = ureq::get(format!("{}/v1/openapi.yaml", env.url))
        .call()
        .unwrap()
        .into_body()
        .read_to_string()
        .unwrap();
    let committed =
        std::fs::read_to_string(aobake_e2e::repo().join("api-spec/openapi.yaml")).unwrap();
    assert!(
        served == committed,
        "GET /v1/openapi.yaml is not api-spec/openapi.yaml"
    );
}

/// The status of a request, its body left unread.
fn status_only(env: &TestEnv, method: &str, path: &str, token: &str) -> u16 {
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let req = ureq::http::Request::builder()
        .method(method)
        .uri(format!("{}{path}", env.url))
        .header("authorization", format!("Bearer {token}"));
    let res = if method == "HEAD" {
        agent.run(req.body(()).unwrap())
    } else {
        agent.run(
            req.header("content-type", "application/json")
                .body("{}".to_owned())
                .unwrap(),
        )
    };
    res.unwrap().status().as_u16()
}

/// A raw request: status, headers and body text.
fn raw(
    env: &TestEnv,
    method: &str,
    path: &str,
    authorization: &str,
    body: &[u8],
) -> (u16, ureq::http::HeaderMap, Vec<u8>) {
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let req = ureq::http::Request::builder()
        .method(method)
        .uri(format!("{}{path}", env.url))
        .header("authorization", authorization)
        .body(body.to_vec())
        .unwrap();
    let mut res = agent.run(req).unwrap();
    let bytes = res.body_mut().read_to_vec().unwrap();
    (res.status().as_u16(), res.headers().clone(), bytes)
}

/// A `read` token reaches what aobake publishes, not the studio's
/// sources: an uploaded character's bytes need `submit`.
#[test]
fn uploaded_sources_need_submit_and_outputs_need_read() {
    let env = TestEnv::start(Options::default());
    let reader = format!("Bearer {}", env.token(&["read"]));
    let submitter = format!("Bearer {}", env.token(&["submit"]));
    let worker = format!("Bearer {}", env.token(&["worker"]));
    let source = std::fs::read(aobake_e2e::character("RiggedSimple")).unwrap();
    let (status, body, _) = env.post_bytes(
        "/v1/characters",
        aobake_e2e::ADMIN,
        "model/gltf-binary",
        &source,
    );
    assert!(status == 201 || status == 200, "{status} {body}");
    let digest = body["digest"].as_str().unwrap();

    let (status, headers, bytes) = raw(&env, "GET", &format!("/v1/assets/{digest}"), &reader, b"");
    assert_eq!(status, 403, "{}", String::from_utf8_lossy(&bytes));
    assert_eq!(headers["content-type"], "application/problem+json");
    let problem: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    assert!(
        problem["detail"].as_str().unwrap().contains("submit"),
        "{problem}"
    );
    let (status, _, bytes) = raw(
        &env,
        "GET",
        &format!("/v1/assets/{digest}"),
        &submitter,
        b"",
    );
    assert_eq!(status, 200);
    assert!(
        bytes == source,
        "a submit token reads back what was uploaded"
    );
    // …and, including `read`, follows its bakes.
    let (status, _, _) = raw(&env, "GET", "/v1/bakes", &submitter, b"");
    assert_eq!(status, 200);

    // An output (any blob that is not an upload) reads with `read`.
    let output = b"an output a worker published".to_vec();
    let out_digest = aobake_core::digest::sha256_hex(&output);
    let (status, _, _) = raw(
        &env,
        "PUT",
        &format!("/v1/blobs/{out_digest}"),
        &worker,
        &output,
    );
    assert!(status == 201 || status == 200 || status == 204, "{status}");
    let (status, _, bytes) = raw(
        &env,
        "GET",
        &format!("/v1/assets/{out_digest}"),
        &reader,
        b"",
    );
    assert_eq!((status, bytes), (200, output.clone()));
    // `submit` includes `read`: it fetches outputs too.
    let (status, _, bytes) = raw(
        &env,
        "GET",
        &format!("/v1/assets/{out_digest}"),
        &submitter,
        b"",
    );
    assert_eq!((status, bytes), (200, output));
}

/// The scheme of `Authorization` is case-insensitive (RFC 9110 §11.1);
/// another scheme is refused.
#[test]
fn the_bearer_scheme_is_case_insensitive() {
    let env = TestEnv::start(Options::default());
    let token = env.token(&["read"]);
    for scheme in ["Bearer", "bearer", "BEARER", "bEaReR"] {
        let (status, _, body) = raw(&env, "GET", "/v1/whoami", &format!("{scheme} {token}"), b"");
        assert_eq!(status, 200, "{scheme}: {}", String::from_utf8_lossy(&body));
    }
    for header in [
        format!("Basic {token}"),
        format!("Bearer{token}"),
        token.clone(),
    ] {
        let (status, _, _) = raw(&env, "GET", "/v1/whoami", &header, b"");
        assert_eq!(status, 401, "{header}");
    }
}

/// An unknown route and a wrong method answer problem+json like every
/// other error, with the request's id.
#[test]
fn unknown_routes_and_wrong_methods_are_problems_too() {
    let env = TestEnv::start(Options::default());
    let admin = format!("Bearer {}", aobake_e2e::ADMIN);
    for (method, path, status, code) in [
        ("GET", "/v1/nothing-here", 404, "not_found"),
        ("POST", "/nowhere/at/all", 404, "not_found"),
        ("DELETE", "/v1/bakes", 405, "method_not_allowed"),
        ("PUT", "/v1/whoami", 405, "method_not_allowed"),
    ] {
        let (got, headers, body) = raw(&env, method, path, &admin, b"");
        assert_eq!(got, status, "{method} {path}");
        assert_eq!(
            headers["content-type"], "application/problem+json",
            "{method} {path}"
        );
        assert!(
            headers.contains_key("x-request-id"),
            "{method} {path}: {headers:?}"
        );
        let problem: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(problem["code"], code, "{problem}");
        assert_eq!(problem["status"], status, "{problem}");
        assert!(
            problem["detail"].as_str().unwrap().contains(path),
            "{problem}"
        );
        if status == 405 {
            assert!(
                headers.contains_key("allow"),
                "{method} {path}: {headers:?}"
            );
        }
    }
}

/// A worker whose token the server refuses (not valid, or without the
/// `worker` scope), or whose `--server` is not an aobake server, will be
/// refused however long it waits: it exits with an error that says what to
/// check, instead of retrying forever under a supervisor.
#[test]
fn a_worker_refused_for_good_exits_saying_why() {
    let env = TestEnv::start(Options::default());
    // Another web service: an app's page for every path (200, HTML), and a
    // static file server that allows no POST (405).
    let page = other_service("200 OK", "text/html", "<!doctype html><title>Shop</title>");
    let files = other_service("405 Method Not Allowed", "text/plain", "Method Not Allowed");
    let worker = env.token(&["worker"]);
    for (server, token, status, check) in [
        (
            env.url.clone(),
            "not-a-token".to_owned(),
            "401",
            "the token is not valid on this server",
        ),
        (
            env.url.clone(),
            env.token(&["read"]),
            "403",
            "the token lacks the worker scope",
        ),
        (
            page,
            worker.clone(),
            "unexpected answer",
            "not as an aobake server does",
        ),
        (
            files,
            worker,
            "405",
            "is not the address of an aobake server",
        ),
    ] {
        let (exit, stderr) = crate::util::worker_until_it_exits(&server, &token, &[]);
        assert_eq!(exit.code(), Some(3), "{status}: {stderr}");
        assert!(
            stderr.contains("refused to lease jobs")
                && stderr.contains(status)
                && stderr.contains(check),
            "{stderr}"
        );
        // Its last line is stamped as every line of its log is.
        let last = stderr
            .lines()
            .rfind(|l| l.contains("refused to lease jobs"))
            .unwrap();
        let stamp = last.split(' ').next().unwrap();
        assert!(humantime::parse_rfc3339(stamp).is_ok(), "{last}");
    }
}

/// The address of a web server that answers every request with `status`
/// and `body`, for as long as the test runs.
fn other_service(status: &'static str, content_type: &'static str, body: &'static str) -> String {
    counted_service(status, content_type, body).0
}

/// [`other_service`], and the count of requests it has answered.
fn counted_service(
    status: &'static str,
    content_type: &'static str,
    body: &'static str,
) -> (String, std::sync::Arc<std::sync::atomic::AtomicUsize>) {
    use std::io::{Read as _, Write as _};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let count = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let counted = count.clone();
    std::thread::spawn(move || {
        for mut stream in listener.incoming().flatten() {
            counted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let _ = stream.set_read_timeout(Some(std::time::Duration::from_millis(200)));
            // The request's head and as much of its body as comes at once.
            let _ = stream.read(&mut [0u8; 1 << 16]);
            let _ = write!(
                stream,
                "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                body.len()
            );
        }
    });
    (url, count)
}

/// A server that answers every lease request at once with no job (204:
/// as an aobake server does when it ends its polls to shut down) is asked
/// again after a growing pause, not hundreds of times a second, and the
/// worker says what it sees.
#[test]
fn a_worker_answered_at_once_with_no_job_asks_again_after_a_pause() {
    // The stand-in server checks no token.
    let (url, requests) = counted_service("204 No Content", "text/plain", "");
    let mut child = std::process::Command::new(aobake_e2e::binary())
        .args(["worker", "--server", &url, "--id", "early", "--gpu", "off"])
        .args(["--token", "any-token"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(6));
    let _ = child.kill();
    let _ = child.wait();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    // Pauses of 0.25, 0.5, 1, 2 and 4 s: about 6 requests in 6 s.
    let asked = requests.load(std::sync::atomic::Ordering::Relaxed);
    assert!(
        (3..=10).contains(&asked),
        "{asked} requests in 6 s\n{stderr}"
    );
    assert!(
        stderr.contains("answers every lease request at once with no job"),
        "{stderr}"
    );
}

/// Tokens are listed (never their secrets) and revoked: a revoked token is
/// refused from its next request on; an admin cannot revoke the token it
/// calls with (one must be left).
#[test]
fn tokens_are_listed_and_revoked_at_once() {
    let mut env = TestEnv::start(Options::default());
    let out = env.aobake(&["token", "create", "--scope", "submit", "--name", "ci"]);
    assert!(out.status.success(), "{out:?}");
    let ci = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    assert_eq!(env.request("GET", "/v1/bakes", &ci, None).unwrap().0, 200);

    let out = env.aobake(&["token", "list", "--json"]);
    let listed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let listed = listed.as_array().unwrap();
    assert_eq!(listed[0]["name"], "ci", "newest first: {listed:?}");
    assert!(
        !out.stdout.windows(ci.len()).any(|w| w == ci.as_bytes()),
        "no secret listed"
    );
    let id = listed[0]["id"].as_str().unwrap().to_owned();
    let admin = listed.iter().find(|t| t["current"] == true).unwrap();
    assert_eq!(admin["scopes"], json!(["admin"]));
    // A long name (as serve gives its own tokens) widens its column: the
    // table stays aligned.
    let long = "a name longer than the column was, 0123456789";
    let made = env.aobake(&["token", "create", "--scope", "read", "--name", long]);
    assert!(made.status.success(), "{made:?}");
    let table = env.aobake(&["token", "list"]);
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(
        table.contains(&id[..12]) && table.contains("(this token)") && table.contains(long),
        "{table}"
    );
    let mut rows = table.lines();
    let column = rows.next().unwrap().find("created").unwrap();
    for row in rows {
        let (before, after) = row.split_at(column);
        assert!(before.ends_with("  ") && !after.starts_with(' '), "{table}");
    }

    // The ci token was used: its last use is listed (the admin's too).
    let ci_row = table.lines().find(|l| l.starts_with(&id[..12])).unwrap();
    assert!(ci_row.ends_with(" s ago"), "{table}");
    // The token the listing is made with is in use now.
    let this = table.lines().find(|l| l.ends_with("(this token)")).unwrap();
    assert!(this.ends_with("  now  (this token)"), "{table}");

    // A token that expires works until then, and is refused after with a
    // reason; the list says it expired.
    let out = env.aobake(&[
        "token",
        "create",
        "--scope",
        "read",
        "--name",
        "brief",
        "--expires-in",
        "2s",
    ]);
    assert!(out.status.success(), "{out:?}");
    let brief = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    assert_eq!(
        env.request("GET", "/v1/bakes", &brief, None).unwrap().0,
        200
    );
    std::thread::sleep(std::time::Duration::from_millis(2200));
    let (status, problem) = env.request("GET", "/v1/bakes", &brief, None).unwrap();
    assert_eq!(
        (status, problem["code"].as_str()),
        (401, Some("token_expired")),
        "{problem}"
    );
    assert!(
        problem["detail"].as_str().unwrap().contains("expired at"),
        "{problem}"
    );
    let out = env
        .aobake_command(&["status", "1"])
        .env("AOBAKE_TOKEN", &brief)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(6), "{out:?}");
    let table = env.aobake(&["token", "list"]);
    let table = String::from_utf8_lossy(&table.stdout);
    let brief_row = table.lines().find(|l| l.contains("brief")).unwrap();
    assert!(
        brief_row.contains("  expired ") && brief_row.contains(" s ago"),
        "{table}"
    );
    let (status, _) = env
        .request(
            "POST",
            "/v1/tokens",
            aobake_e2e::ADMIN,
            Some(json!({"name": "x", "scopes": ["read"], "expires_in_secs": 0})),
        )
        .unwrap();
    assert_eq!(status, 400);

    let out = env.aobake(&["token", "revoke", &id[..10]]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("revoked"),
        "{out:?}"
    );
    let (status, problem) = env.request("GET", "/v1/bakes", &ci, None).unwrap();
    assert_eq!(status, 401, "a revoked token is refused at once: {problem}");
    // No token matches now: the input is refused (5); a start too short
    // to name one is a wrong command line (2).
    let out = env.aobake(&["token", "revoke", &id[..10]]);
    assert_eq!(out.status.code(), Some(5), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no token's id starts with"),
        "{out:?}"
    );
    let out = env.aobake(&["token", "revoke", &id[..4]]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");

    let own = admin["id"].as_str().unwrap();
    let (status, problem) = env
        .request(
            "DELETE",
            &format!("/v1/tokens/{own}"),
            aobake_e2e::ADMIN,
            None,
        )
        .unwrap();
    assert_eq!(status, 409, "{problem}");
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("another admin token"),
        "{problem}"
    );
    let (status, _) = env
        .request(
            "DELETE",
            &format!("/v1/tokens/{}", "0".repeat(64)),
            aobake_e2e::ADMIN,
            None,
        )
        .unwrap();
    assert_eq!(status, 404);
    let (status, problem) = env
        .request("DELETE", "/v1/tokens/not-an-id", aobake_e2e::ADMIN, None)
        .unwrap();
    assert_eq!(
        (status, &problem["code"]),
        (400, &json!("bad_token_id")),
        "{problem}"
    );

    // A start without local workers (as here: the workers are separate
    // processes) makes no token for them, neither at the first start nor
    // at a restart; the operator's admin token stays. (A start with local
    // workers revokes the earlier start's at a restart: the server's
    // integration tests.)
    let names = |env: &TestEnv| -> Vec<String> {
        let (_, listed) = env
            .request("GET", "/v1/tokens", aobake_e2e::ADMIN, None)
            .unwrap();
        listed
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["name"].as_str().unwrap().to_owned())
            .collect()
    };
    let local = |names: &[String]| names.iter().any(|n| n.starts_with("local workers"));
    let before = names(&env);
    assert!(
        !local(&before) && before.contains(&"admin".to_owned()),
        "{before:?}"
    );
    env.kill_server();
    env.start_server();
    let after = names(&env);
    assert!(
        !local(&after) && after.contains(&"admin".to_owned()),
        "{after:?}"
    );
}

/// An open event stream (a dashboard tab) ends soon after its token is
/// revoked or expires, so it stops hearing what the token may no longer
/// read; its reconnection then gets the 401.
#[test]
fn an_event_stream_ends_when_its_token_is_revoked_or_expires() {
    use std::io::Read as _;
    use std::time::{Duration, Instant};
    let env = TestEnv::start(Options::default());
    // Streams /v1/events with `token` on a thread; says when it ended.
    let listen = |token: String| {
        let url = format!("{}/v1/events", env.url);
        let (tx, rx) = std::sync::mpsc::channel::<Instant>();
        std::thread::spawn(move || {
            let res = ureq::get(&url)
                .header("authorization", format!("Bearer {token}"))
                .call()
                .unwrap();
            let mut sink = Vec::new();
            let _ = res.into_body().into_reader().read_to_end(&mut sink);
            let _ = tx.send(Instant::now());
        });
        rx
    };
    let create = |body: serde_json::Value| {
        let (status, made) = env
            .request("POST", "/v1/tokens", aobake_e2e::ADMIN, Some(body))
            .unwrap();
        assert_eq!(status, 201, "{made}");
        made["token"].as_str().unwrap().to_owned()
    };
    let revoked = create(json!({"name": "tab", "scopes": ["read"]}));
    let expiring = create(json!({"name": "brief tab", "scopes": ["read"], "expires_in_secs": 2}));
    let kept = create(json!({"name": "kept tab", "scopes": ["read"]}));
    let opened = Instant::now();
    let (a, b, c) = (
        listen(revoked.clone()),
        listen(expiring.clone()),
        listen(kept),
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(a.try_recv().is_err(), "a valid token's stream stays open");
    let id = aobake_core::digest::sha256_hex(revoked.as_bytes());
    let (status, _) = env
        .request(
            "DELETE",
            &format!("/v1/tokens/{id}"),
            aobake_e2e::ADMIN,
            None,
        )
        .unwrap();
    assert_eq!(status, 204);
    let at = Instant::now();
    let ended = a
        .recv_timeout(Duration::from_secs(15))
        .expect("the revoked token's stream ended");
    assert!(ended - at < Duration::from_secs(8), "{:?}", ended - at);
    b.recv_timeout(Duration::from_secs(15))
        .expect("the expired token's stream ended");
    assert_eq!(
        env.request("GET", "/v1/events", &expiring, None).unwrap().0,
        401
    );
    // A valid token's stream outlives two of the checks (every 5 s).
    std::thread::sleep(Duration::from_secs(11).saturating_sub(opened.elapsed()));
    assert!(c.try_recv().is_err(), "a valid token's stream stays open");
}
