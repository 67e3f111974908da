//! # aobake-runtime
//!
//! What playing a baked AO asset takes, apart from everything that bakes
//! one: the versioned container (magic, version, the method, a JSON
//! header and typed, checksummed sections; `docs/asset-format.md`), the
//! rig and the pose features the vertex methods read, and each family's
//! run time: per-vertex AO from the local transforms of named nodes
//! ([`method::vertex::VertexAo`]), the cubemap lookup at a point and a
//! phase ([`method::cubemap`]), the grid lookup at a point and a normal
//! ([`method::grid`]). [`Asset::from_bytes`] reads any of them.
//!
//! aobake's core, worker and CLI read assets through it, and so do
//! engines (in Rust, or in C, C++ and C# through `runtime/capi`;
//! `docs/engines.md`). It must not depend on a ray tracer, linear
//! algebra, a glTF reader or an async runtime (no obvhs, faer, gltf, tokio
//! or axum; DESIGN §2): a test holds it to its short list of
//! dependencies.
//!
//! Layers, bottom up: `container`, `rig`, `pose_space`, `method` (a
//! method's identity; each family's run time and codec in its folder
//! below it), `asset`.

pub mod asset;
pub mod container;
pub mod method;
pub mod pose_space;
pub mod rig;

pub use asset::Asset;
pub use container::{AssetError, Container, Data, MAGIC, MAJOR, MINOR, PrimitiveSpan, Section};
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
