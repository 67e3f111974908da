//! The dashboard (DESIGN §1, §2): plain HTML, CSS and JavaScript compiled
//! into the binary, served at `/` with no build step and no network
//! beyond this server. The pages read the API with the user's token
//! (`/v1/whoami` says what it may do) and follow bakes live over the API's
//! server-sent events. The files hold no data, so they are public; the
//! Content-Security-Policy allows only this origin and the object URLs the
//! pages make of images they fetched with the token.

use axum::{
    Router,
    http::{HeaderValue, StatusCode, header},
    response::{IntoResponse, Response},
    routing::get,
};

use crate::state::AppState;

const INDEX: &str = include_str!("assets/index.html");
const APP: &str = include_str!("assets/app.js");
const VIEWER: &str = include_str!("assets/viewer.js");
const STYLE: &str = include_str!("assets/style.css");
const ICON: &str = include_str!("assets/icon.svg");

const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob:; connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

pub(crate) fn router() -> Router<AppState> {
    Router::new()
        .route(
            "/",
            get(|| async { file(INDEX, "text/html; charset=utf-8") }),
        )
        .route(
            "/dashboard/app.js",
            get(|| async { file(APP, "text/javascript; charset=utf-8") }),
        )
        .route(
            "/dashboard/viewer.js",
            get(|| async { file(VIEWER, "text/javascript; charset=utf-8") }),
        )
        .route(
            "/dashboard/style.css",
            get(|| async { file(STYLE, "text/css; charset=utf-8") }),
        )
        // The tab's icon (without one, browsers ask for /favicon.ico and
        // log its 404 as an error on every page).
        .route(
            "/dashboard/icon.svg",
            get(|| async { file(ICON, "image/svg+xml") }),
        )
}

fn file(body: &'static str, content_type: &'static str) -> Response {
    (
        StatusCode::OK,
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (
                header::CONTENT_SECURITY_POLICY,
                HeaderValue::from_static(CSP),
            ),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
            (
                header::X_CONTENT_TYPE_OPTIONS,
                HeaderValue::from_static("nosniff"),
            ),
        ],
        body,
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_loads_only_files_this_module_serves() {
        for path in [
            "/dashboard/app.js",
            "/dashboard/style.css",
            "/dashboard/icon.svg",
        ] {
            assert!(INDEX.contains(path), "{path}");
        }
        assert!(!INDEX.contains("http://") && !INDEX.contains("https://"));
        for script in [APP, VIEWER] {
            assert!(
                !script.contains("http://") && !script.contains("https://"),
                "works offline"
            );
        }
        assert!(APP.contains("\"./viewer.js\""));
    }
}
