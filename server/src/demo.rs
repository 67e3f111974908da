//! `aobake serve --demo`: uploads the bundled Fox, starts a fresh bake of
//! it with Kirk & Arikan's method and prints a URL that opens the
//! dashboard on that bake.

use aobake_api::{BakeRequest, Client};
use serde_json::json;

/// The bundled Fox (glTF sample models, CC BY 4.0: see
/// tests/data/characters/Fox/SOURCE.md).
static FOX: &[u8] = include_bytes!("../../tests/data/characters/Fox/Fox.glb");

/// Uploads the bundled Fox as the admin at `url`, bakes it, and prints
/// the dashboard's address with `dashboard`, a read-and-submit token
/// `serve` made for it (and revokes at its next start): at `url`, and at
/// `public` too where that differs (https, for other machines).
pub(crate) async fn run(
    url: &str,
    public: &str,
    token: &str,
    dashboard: &str,
) -> anyhow::Result<()> {
    let (url, public, token, dashboard) = (
        url.to_owned(),
        public.to_owned(),
        token.to_owned(),
        dashboard.to_owned(),
    );
    tokio::task::spawn_blocking(move || {
        let api = Client::new(&url, &token);
        let c = api.upload_character(FOX, false, "Fox.glb")?;
        let seed = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let params = serde_json::Map::from_iter([("seed".to_owned(), json!(seed))]);
        let bake = api.submit(&BakeRequest::new(c.digest, "vertex-clustered", params))?;
        let id = bake.bake.id;
        let page = format!("#token={dashboard}&next=/bakes/{id}");
        let elsewhere = if public == url {
            String::new()
        } else {
            format!(" on this machine, or {public}/{page} from others")
        };
        println!(
            "{} demo: baking the bundled Fox (vertex-clustered, seed {seed}: a fresh bake each time) as bake {id}\n\n  open {url}/{page}{elsewhere}\n\nto watch it in the dashboard (or `aobake status {id}`)",
            aobake_worker::stamp()
        );
        anyhow::Ok(())
    })
    .await?
}
