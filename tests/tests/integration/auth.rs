//! A wrong or missing token gets 401, a token without the scope 403, on
//! every route (the health probes excepted: load balancers call them
//! without a token).

use aobake_e2e::{Options, TestEnv};
use serde_json::json;

/// Every authenticated route, the scope it needs, and a body.
fn routes() -> Vec<(&'static str, String, &'static str)> {
    let d = "a".repeat(64);
    vec![
        ("POST", "/v1/characters".into(), "submit"),
        ("GET", format!("/v1/characters/{d}"), "read"),
        ("GET", format!("/v1/characters/{d}/bakes"), "read"),
        ("POST", format!("/v1/clips?character={d}"), "submit"),
        ("GET", format!("/v1/clips/{d}"), "read"),
        ("POST", "/v1/bakes".into(), "submit"),
        ("GET", "/v1/bakes".into(), "read"),
        ("GET", "/v1/bakes/1".into(), "read"),
        ("PATCH", "/v1/bakes/1".into(), "submit"),
        ("GET", "/v1/bakes/1/report".into(), "read"),
        ("GET", "/v1/bakes/1/events".into(), "read"),
        ("POST", "/v1/bakes/1/cancel".into(), "submit"),
        ("POST", "/v1/bakes/1/pause".into(), "submit"),
        ("POST", "/v1/bakes/1/resume".into(), "submit"),
        ("POST", "/v1/bakes/1/retry".into(), "submit"),
        ("GET", format!("/v1/cache/{d}"), "read"),
        ("GET", format!("/v1/assets/{d}"), "read"),
        ("POST", "/v1/jobs/lease".into(), "worker"),
        ("POST", "/v1/jobs/1/heartbeat".into(), "worker"),
        ("POST", "/v1/jobs/1/checkpoint".into(), "worker"),
        ("POST", "/v1/jobs/1/complete".into(), "worker"),
        ("POST", "/v1/jobs/1/fail".into(), "worker"),
        ("POST", "/v1/jobs/1/release".into(), "worker"),
        ("GET", format!("/v1/blobs/{d}"), "worker"),
        ("PUT", format!("/v1/blobs/{d}"), "worker"),
        ("GET", "/v1/workers".into(), "read"),
        ("POST", "/v1/tokens".into(), "admin"),
        ("GET", "/metrics".into(), "read"),
    ]
}

/// The route table of this test and of the spec agree.
pub(crate) fn covered() -> Vec<(String, String)> {
    routes()
        .into_iter()
        .map(|(m, p, _)| (m.to_owned(), p))
        .collect()
}

#[test]
fn every_route_refuses_missing_wrong_and_unscoped_tokens() {
    let env = TestEnv::start(Options::default());
    let tokens: Vec<(&str, String)> = ["read", "submit", "worker"]
        .into_iter()
        .map(|s| (s, env.token(&[s])))
        .collect();
    let body = json!({});
    for (method, path, scope) in routes() {
        for (token, what) in [("", "no token"), ("not-a-token", "a wrong token")] {
            let (status, answer) = env
                .request(method, &path, token, Some(body.clone()))
                .unwrap();
            assert_eq!(status, 401, "{method} {path} with {what}: {answer}");
            assert_eq!(answer["code"], "unauthorized");
        }
        for (s, token) in &tokens {
            let (status, answer) = env
                .request(method, &path, token, Some(body.clone()))
                .unwrap();
            if *s == scope {
                assert!(
                    status != 401 && status != 403,
                    "{method} {path} refused its own scope {s}: {status} {answer}"
                );
            } else {
                assert_eq!(status, 403, "{method} {path} with a {s} token: {answer}");
                assert_eq!(answer["code"], "forbidden");
            }
        }
    }
    for probe in ["/healthz", "/readyz"] {
        assert_eq!(env.request("GET", probe, "", None).unwrap().0, 200);
    }
}
