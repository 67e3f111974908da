//! The HTTP API under `/v1`, one file per resource, each route beside its
//! handler (STYLE: axum examples).

pub(crate) mod assets;
pub(crate) mod bakes;
pub(crate) mod jobs;
pub(crate) mod system;
pub(crate) mod uploads;
pub(crate) mod viewer;

use axum::Router;

use crate::state::AppState;

/// Every route.
pub(crate) fn router() -> Router<AppState> {
    Router::new()
        .merge(uploads::router())
        .merge(bakes::router())
        .merge(jobs::router())
        .merge(assets::router())
        .merge(system::router())
        .merge(viewer::router())
}
