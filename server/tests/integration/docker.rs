//! docker/: every aobake command of the compose file and the image is one
//! the command line takes (with the values the file gives its
//! variables), every `AOBAKE_` variable set is one aobake reads, and the
//! services wait on health checks that exist. This machine has no Docker
//! engine; this is what keeps the files from drifting from the binary.

use aobake_server::{cli::Cli, serve::ADMIN_TOKEN_ENV};
use clap::{CommandFactory as _, Parser as _};
use serde_norway::Value;

use super::repo;

fn yaml(path: &str) -> Value {
    serde_norway::from_str(&std::fs::read_to_string(repo().join(path)).unwrap()).unwrap()
}

fn strings(v: &Value) -> Vec<String> {
    v.as_sequence()
        .unwrap_or_else(|| panic!("not a list: {v:?}"))
        .iter()
        .map(|s| s.as_str().unwrap().to_owned())
        .collect()
}

/// `aobake ARGS…` as the binary would parse it.
fn parses(args: &[String]) -> Result<(), clap::Error> {
    Cli::try_parse_from(std::iter::once("aobake").chain(args.iter().map(String::as_str)))
        .map(|_| ())
}

/// The flag of subcommand `sub` that reads the environment variable `var`.
fn flag_of(sub: &str, var: &str) -> Option<String> {
    let cli = Cli::command();
    let sub = cli.find_subcommand(sub)?;
    sub.get_arguments()
        .find(|a| a.get_env().is_some_and(|e| e == var))
        .and_then(|a| a.get_long())
        .map(|l| format!("--{l}"))
}

/// The value compose gives `${VAR:-default}` or a literal; a stand-in for
/// a variable without a default (a secret the user sets).
fn value(v: &Value) -> String {
    let v = v.as_str().unwrap();
    match v.strip_prefix("${") {
        Some(rest) => rest
            .split_once(":-")
            .map_or("a-secret".to_owned(), |(_, d)| {
                d.trim_end_matches('}').to_owned()
            }),
        None => v.to_owned(),
    }
}

#[test]
fn the_docker_files_run_commands_aobake_takes() {
    let compose = yaml("docker/compose.yaml");
    let services = compose["services"].as_mapping().unwrap();
    let mut ours = 0;
    for (name, service) in services {
        let name = name.as_str().unwrap();
        if service["build"]["dockerfile"].as_str() != Some("docker/Dockerfile") {
            continue;
        }
        ours += 1;
        let mut args = strings(&service["command"]);
        let sub = args[0].clone();
        // Each AOBAKE_ variable is read by the subcommand, and the value
        // the file gives it is one the flag takes.
        for (var, v) in service["environment"].as_mapping().into_iter().flatten() {
            let var = var.as_str().unwrap();
            if !var.starts_with("AOBAKE_") {
                continue;
            }
            if sub == "serve" && var == ADMIN_TOKEN_ENV {
                continue;
            }
            let flag =
                flag_of(&sub, var).unwrap_or_else(|| panic!("{name}: aobake {sub} reads no {var}"));
            args.extend([flag, value(v)]);
        }
        if let Err(e) = parses(&args) {
            panic!("{name}: aobake {args:?} (its variables as flags): {e}");
        }
        // Workers start once the server is ready, and say how they trace.
        if sub == "worker" {
            assert_eq!(
                service["depends_on"]["server"]["condition"].as_str(),
                Some("service_healthy"),
                "{name}"
            );
            assert!(args.iter().any(|a| a == "--gpu"), "{name}: no AOBAKE_GPU");
        }
    }
    assert_eq!(ours, 3, "server, worker and gpu-worker");

    // PostgreSQL's and the object store's health checks, and the server's
    // on a route it serves; the server keeps its blobs in that store.
    assert_eq!(
        strings(&compose["services"]["postgres"]["healthcheck"]["test"])[1],
        "pg_isready"
    );
    assert!(compose["services"]["s3"]["healthcheck"]["test"].is_sequence());
    let serve = strings(&compose["services"]["server"]["command"]);
    let blobs = serve.iter().skip_while(|a| *a != "--blobs").nth(1);
    assert!(
        blobs.is_some_and(|b| b.starts_with("s3://") && b.contains("endpoint=http://s3:")),
        "{serve:?}"
    );
    // Its settings are ones the S3 client takes.
    aobake_server::blobs::open(blobs.unwrap()).unwrap();
    let check = strings(&compose["services"]["server"]["healthcheck"]["test"]);
    let path = check
        .last()
        .and_then(|url| url.split_once(":8080"))
        .map(|(_, path)| path.to_owned())
        .unwrap();
    let spec = yaml("api-spec/openapi.yaml");
    assert!(spec["paths"][path.as_str()].is_mapping(), "{path}");

    // The image runs aobake, its default command parses, and it has the
    // tool the server's health check runs.
    let dockerfile = std::fs::read_to_string(repo().join("docker/Dockerfile")).unwrap();
    let directive = |name: &str| -> Vec<String> {
        let line = dockerfile
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .unwrap_or_else(|| panic!("no {name}"));
        serde_json::from_str(line.trim()).unwrap()
    };
    assert_eq!(directive("ENTRYPOINT "), ["aobake"]);
    let cmd = directive("CMD ");
    parses(&cmd).unwrap_or_else(|e| panic!("CMD {cmd:?}: {e}"));
    let tool = &check[1];
    assert!(
        dockerfile.contains(&format!(" {tool} ")) || dockerfile.contains(&format!(" {tool}\n")),
        "the image does not install {tool}"
    );
}
