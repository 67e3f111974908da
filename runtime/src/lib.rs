//! # aobake-runtime
//!
//! What reading a baked AO asset takes, apart from everything that bakes
//! one: the versioned container (magic, version, the method, a JSON
//! header and typed, checksummed sections; `docs/asset-format.md`) and the
//! method an asset holds, and each family's run time (so far the grids
//! and the vertex methods' linear form).
//! aobake's core, worker and CLI read assets
//! through it, and so can an engine's tools. It must not depend on a ray
//! tracer, linear algebra, a glTF reader or an async runtime (no obvhs,
//! faer, gltf, tokio or axum; DESIGN §2): a test holds it to its short
//! list of dependencies.
//!
//! Layers, bottom up: `method` (a method's identity; each family's run
//! time in its folder below it: [`method::grid`], [`method::vertex`] in
//! part), `container`.
//! Each family's codec reads and writes the container.

pub mod container;
pub mod method;
pub mod pose_space;
pub mod rig;

pub use container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, Section};
pub use method::{Family, Method};

#[cfg(test)]
mod tests {
    /// The crate stays small enough for an engine's build: a dependency
    /// beyond this list is a decision to make here, in the open.
    #[test]
    fn depends_only_on_small_crates() {
        let manifest = include_str!("../Cargo.toml");
        let deps: Vec<&str> = manifest
            .split("[dependencies]")
            .nth(1)
            .expect("a [dependencies] table")
            .split("\n[")
            .next()
            .unwrap_or_default()
            .lines()
            .filter_map(|l| l.split(['.', ' ', '=']).next())
            .filter(|name| !name.is_empty() && !name.starts_with('#'))
            .collect();
        let allowed = [
            "crc32fast",
            "glam",
            "half",
            "serde",
            "serde_json",
            "thiserror",
        ];
        for d in &deps {
            assert!(allowed.contains(d), "aobake-runtime depends on {d}");
        }
        assert!(!deps.is_empty(), "the table was read: {deps:?}");
    }
}
