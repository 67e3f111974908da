//! The OpenAPI 3.1 description of the HTTP API, generated from the
//! handlers' annotations (utoipa). `api-spec/openapi.yaml` is this
//! document, committed; a test fails when the two differ, and `aobake
//! openapi` prints it.

use utoipa::{
    Modify, OpenApi,
    openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme},
};

use crate::routes::{assets, bakes, jobs, system, uploads, viewer};

use aobake_api::schema::Digest;

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(
                        "A token with the scope each operation names: read, submit, worker or admin (admin has all).",
                    ))
                    .build(),
            ),
        );
    }
}

/// The API.
#[derive(Debug, OpenApi)]
#[openapi(
    info(
        title = "aobake",
        version = "1",
        description = "Pose-dependent ambient occlusion baked as a service: upload glTF characters and clips, bake, follow progress, fetch versioned assets by bake key. Every error is RFC 9457 problem+json; every response carries an x-request-id."
    ),
    paths(
        uploads::post_character,
        uploads::get_upload,
        uploads::post_clips,
        uploads::get_clips,
        bakes::submit,
        bakes::list,
        bakes::versions,
        bakes::show,
        bakes::report,
        bakes::previews,
        viewer::scene,
        viewer::frames,
        assets::preview,
        assets::preview_head,
        bakes::patch,
        bakes::control,
        bakes::cache,
        bakes::key,
        bakes::events,
        bakes::all_events,
        system::whoami,
        assets::asset,
        assets::asset_head,
        jobs::lease,
        jobs::lease_many,
        jobs::heartbeat,
        jobs::checkpoint,
        jobs::complete,
        jobs::complete_many,
        jobs::fail,
        jobs::release,
        jobs::workers_stopped,
        jobs::get_blob,
        jobs::put_blob,
        system::workers,
        system::create_token,
        system::tokens,
        system::revoke_token,
        system::healthz,
        system::openapi,
        system::ready,
        system::metrics,
    ),
    components(schemas(Digest)),
    modifiers(&BearerAuth),
    tags(
        (name = "uploads", description = "Characters and clips, content-addressed"),
        (name = "bakes", description = "Submit, follow, control; the cache by bake key"),
        (name = "assets", description = "Published bytes by digest"),
        (name = "worker protocol", description = "What worker processes call"),
        (name = "system", description = "Workers, tokens, health, metrics"),
    )
)]
pub struct ApiDoc;

/// The document as YAML.
pub fn yaml() -> String {
    ApiDoc::openapi()
        .to_yaml()
        .expect("the OpenAPI document serialises")
}

#[cfg(test)]
mod tests {
    use utoipa::OpenApi as _;

    /// Every path parameter is in its path's template and every template
    /// variable is a path parameter (a query parameter declared in the
    /// path once slipped through).
    #[test]
    fn path_parameters_are_the_templates_variables() {
        use utoipa::openapi::path::ParameterIn;
        let doc = super::ApiDoc::openapi();
        for (path, item) in &doc.paths.paths {
            let variables: Vec<&str> = path
                .split('{')
                .skip(1)
                .filter_map(|s| s.split('}').next())
                .collect();
            let operations = [&item.get, &item.put, &item.post, &item.delete, &item.patch];
            for op in operations.into_iter().flatten() {
                let params = op.parameters.as_deref().unwrap_or_default();
                let in_path: Vec<&str> = params
                    .iter()
                    .filter(|p| matches!(p.parameter_in, ParameterIn::Path))
                    .map(|p| p.name.as_str())
                    .collect();
                for name in &in_path {
                    assert!(
                        variables.contains(name),
                        "{path}: `{name}` is not in the path"
                    );
                }
                for v in &variables {
                    assert!(
                        in_path.contains(v),
                        "{path}: `{{{v}}}` is not a path parameter"
                    );
                }
            }
        }
    }

    /// A body that is not JSON (assets, blobs, previews, viewer bundles)
    /// is a binary string, which generated clients read as bytes, never
    /// an array of integers.
    #[test]
    fn binary_bodies_are_binary_strings() {
        let doc: serde_json::Value =
            serde_json::to_value(super::ApiDoc::openapi()).expect("the spec serialises");
        let mut checked = 0;
        for (path, item) in doc["paths"].as_object().unwrap() {
            for (method, op) in item.as_object().unwrap() {
                let bodies = op["responses"]
                    .as_object()
                    .into_iter()
                    .flatten()
                    .map(|(_, r)| &r["content"])
                    .chain([&op["requestBody"]["content"]]);
                for content in bodies.filter_map(serde_json::Value::as_object) {
                    for (kind, media) in content {
                        if kind.contains("json") || kind.starts_with("multipart/") {
                            continue;
                        }
                        let schema = &media["schema"];
                        let binary = schema["$ref"] == "#/components/schemas/FileBytes"
                            || (schema["type"] == "string" && schema["format"] == "binary");
                        // Text (server-sent events, metrics, this spec)
                        // is a plain string.
                        let text = (kind.starts_with("text/")
                            || kind.ends_with("-text")
                            || kind.ends_with("yaml"))
                            && schema["type"] == "string";
                        assert!(binary || text, "{method} {path} {kind}: {schema}");
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked >= 8, "{checked}");
    }

    #[test]
    fn the_committed_spec_is_the_generated_one() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../api-spec/openapi.yaml");
        let generated = super::yaml();
        if std::env::var_os("AOBAKE_BLESS").is_some() {
            std::fs::write(path, &generated).unwrap();
        }
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed == generated,
            "api-spec/openapi.yaml is stale: run `aobake openapi > api-spec/openapi.yaml` (or AOBAKE_BLESS=1 cargo test -p aobake-server openapi)"
        );
        assert!(
            generated.starts_with("openapi: 3.1"),
            "{}",
            &generated[..40]
        );
    }
}
