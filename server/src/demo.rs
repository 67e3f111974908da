//! `aobake serve --demo`: uploads the bundled Fox, starts a fresh bake of
//! it with Kirk & Arikan's method and prints a URL that opens the
//! dashboard on that bake.

use aobake_core::bake::UploadBytes;
use serde_json::json;

use crate::cli::client::Api;

/// The bundled Fox (glTF sample models, CC BY 4.0: see
/// tests/data/characters/Fox/SOURCE.md).
static FOX: &[u8] = include_bytes!("../../tests/data/characters/Fox/Fox.glb");

/// Uploads the bundled Fox as the admin at `url` and bakes it.
pub(crate) async fn run(url: &str, token: &str) -> anyhow::Result<()> {
    let (url, token) = (url.to_owned(), token.to_owned());
    tokio::task::spawn_blocking(move || {
        let api = Api::new(&url, &token);
        let c = api.upload("/v1/characters", &UploadBytes::single(FOX.to_vec()), "Fox.glb")?;
        let seed = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let bake = api.post(
            "/v1/bakes",
            &json!({"character": c["digest"], "method": "vertex-clustered", "params": {"seed": seed}}),
        )?;
        let dashboard = api.post(
            "/v1/tokens",
            &json!({"name": "demo dashboard", "scopes": ["read", "submit"]}),
        )?;
        let id = &bake["id"];
        println!(
            "demo: baking the bundled Fox (vertex-clustered) as bake {id}\n\n  open {url}/#token={}&next=/bakes/{id}\n\nto watch it in the dashboard (or `aobake status {id}`)",
            dashboard["token"].as_str().unwrap_or_default()
        );
        anyhow::Ok(())
    })
    .await?
}
