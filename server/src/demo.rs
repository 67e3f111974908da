//! `aobake serve --demo`: uploads the bundled Fox, starts a fresh bake of
//! it with Kirk & Arikan's method and prints a URL that opens the
//! dashboard on that bake.

use aobake_api::{BakeRequest, Client, NewTokenRequest};
use serde_json::json;

/// The bundled Fox (glTF sample models, CC BY 4.0: see
/// tests/data/characters/Fox/SOURCE.md).
static FOX: &[u8] = include_bytes!("../../tests/data/characters/Fox/Fox.glb");

/// Uploads the bundled Fox as the admin at `url` and bakes it.
pub(crate) async fn run(url: &str, token: &str) -> anyhow::Result<()> {
    let (url, token) = (url.to_owned(), token.to_owned());
    tokio::task::spawn_blocking(move || {
        let api = Client::new(&url, &token);
        let c = api.upload_character(FOX, false, "Fox.glb")?;
        let seed = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let params = serde_json::Map::from_iter([("seed".to_owned(), json!(seed))]);
        let bake = api.submit(&BakeRequest::new(c.digest, "vertex-clustered", params))?;
        let dashboard = api.create_token(&NewTokenRequest {
            name: "demo dashboard".to_owned(),
            scopes: vec!["read".to_owned(), "submit".to_owned()],
        })?;
        let id = bake.bake.id;
        println!(
            "demo: baking the bundled Fox (vertex-clustered, seed {seed}: a fresh bake each time) as bake {id}\n\n  open {url}/#token={}&next=/bakes/{id}\n\nto watch it in the dashboard (or `aobake status {id}`)",
            dashboard.token
        );
        anyhow::Ok(())
    })
    .await?
}
