//! Integration tests of aobake-core, one binary (STYLE.md: link once).

#[path = "integration/util.rs"]
mod util;

#[path = "integration/cubemap.rs"]
mod cubemap;
#[path = "integration/grid.rs"]
mod grid;
#[path = "integration/hostile_assets.rs"]
mod hostile_assets;
#[path = "integration/jobs.rs"]
mod jobs;
#[path = "integration/malformed.rs"]
mod malformed;
#[path = "integration/methods.rs"]
mod methods;
#[path = "integration/params.rs"]
mod params;
#[path = "integration/real_characters.rs"]
mod real_characters;
#[path = "integration/skinning.rs"]
mod skinning;
#[path = "integration/synthetic.rs"]
mod synthetic;
#[path = "integration/texel.rs"]
mod texel;
#[path = "integration/tracing.rs"]
mod tracing;
