//! End-to-end tests of the service: real `aobake serve` and `aobake worker`
//! processes on ports the OS picks (one binary, STYLE.md).

#[path = "integration/auth.rs"]
mod auth;
#[path = "integration/bad_input.rs"]
mod bad_input;
#[path = "integration/browser.rs"]
mod browser;
#[path = "integration/cluster.rs"]
mod cluster;
#[path = "integration/crashes.rs"]
mod crashes;
#[path = "integration/cubemap.rs"]
mod cubemap;
#[path = "integration/dashboard.rs"]
mod dashboard;
#[path = "integration/grid.rs"]
mod grid;
#[path = "integration/props.rs"]
mod props;
#[path = "integration/service.rs"]
mod service;
#[path = "integration/texel.rs"]
mod texel;
#[path = "integration/three.rs"]
mod three;
#[path = "integration/tls.rs"]
mod tls;
#[path = "integration/tracer.rs"]
mod tracer;
#[path = "integration/util.rs"]
mod util;
