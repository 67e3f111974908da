//! # aobake-shaders
//!
//! The WGSL of aobake, one file per pipeline under `shaders/wgsl/`, shared
//! pieces under `shaders/wgsl/common/`, embedded with `include_str!` so the
//! worker, the tests (naga validation) and the asset exports use the same
//! text (DESIGN §2). A pipeline's source is its common pieces followed by
//! its own file; [`sources`] lists every composed pipeline.
//!
//! * [`VERTEX_AO`]: run-time per-vertex AO of the vertex methods
//!   (`cs_main` for dense coefficients, `cs_sparse` for CSR), the
//!   evaluation an engine runs per frame.
//! * [`VERTEX_AO_VS`]: the same in a vertex shader (`vertex_ao(v)`; data
//!   in textures), for WebGL2 and GLSL ES 3.00.
//! * [`CUBEMAP_AO`]: run-time lookup of Kroon's cubemaps at points in
//!   space (`cubemap_occlusion`, and `cs_main` over a batch of points).
//! * [`GRID_AO`]: run-time lookup of Malmer et al.'s grids at receivers
//!   (`grid_occlusion`, and `cs_main` over a batch).
//! * [`PREVIEW`]: the preview raster (`vs_main`, `fs_main`).
//! * [`VIEWER`]: the dashboard's WebGL2 viewer: GPU skinning,
//!   `vertex_ao(v)` and the previews' shading, for naga's GLSL ES 3.00.
//!
//! The Rust mirrors of the uniforms and storage structs are in [`mirror`],
//! field for field with size assertions; [`export`] translates the
//! run-time evaluators for engines (GLSL, HLSL, MSL, SPIR-V).

pub mod export;
pub mod mirror;

pub use mirror::{
    BlockInfo, CubemapAoParams, GridAoParams, GridPartInfo, GridReceiver, PreviewUniforms,
    VertexAoParams, VertexAoVsParams,
};

/// Half-float decoding shared by the pipelines.
pub const COMMON_F16: &str = include_str!("../wgsl/common/f16.wgsl");

/// The vertex-method evaluation shader, composed: [`COMMON_F16`] then
/// `vertex_ao.wgsl`.
pub const VERTEX_AO: &str = concat!(
    include_str!("../wgsl/common/f16.wgsl"),
    "\n",
    include_str!("../wgsl/vertex_ao.wgsl")
);

/// The vertex-method evaluation in a vertex shader (textures instead of
/// storage buffers, for WebGL2 and GLSL ES 3.00), composed: [`COMMON_F16`],
/// `common/vertex_ao_textures.wgsl`, then `vertex_ao_vs.wgsl` (the tests'
/// point draw).
pub const VERTEX_AO_VS: &str = concat!(
    include_str!("../wgsl/common/f16.wgsl"),
    "\n",
    include_str!("../wgsl/common/vertex_ao_textures.wgsl"),
    "\n",
    include_str!("../wgsl/vertex_ao_vs.wgsl")
);

/// Texels per row of [`VERTEX_AO_VS`]'s data textures (WebGL2's smallest
/// `MAX_TEXTURE_SIZE`).
pub const VS_TEXTURE_WIDTH: u32 = 2048;

/// The cubemap lookup shader, composed: [`COMMON_F16`] then
/// `cubemap_ao.wgsl`.
pub const CUBEMAP_AO: &str = concat!(
    include_str!("../wgsl/common/f16.wgsl"),
    "\n",
    include_str!("../wgsl/cubemap_ao.wgsl")
);

/// The grid lookup shader.
pub const GRID_AO: &str = include_str!("../wgsl/grid_ao.wgsl");

/// The preview raster shader, composed: `common/shade.wgsl` then
/// `preview.wgsl`.
pub const PREVIEW: &str = concat!(
    include_str!("../wgsl/common/shade.wgsl"),
    "\n",
    include_str!("../wgsl/preview.wgsl")
);

/// The dashboard viewer's shader (WebGL2 through naga's GLSL ES 3.00:
/// [`export::webgl_viewer`]), composed: [`COMMON_F16`],
/// `common/vertex_ao_textures.wgsl`, `common/shade.wgsl`, then
/// `viewer.wgsl`.
pub const VIEWER: &str = concat!(
    include_str!("../wgsl/common/f16.wgsl"),
    "\n",
    include_str!("../wgsl/common/vertex_ao_textures.wgsl"),
    "\n",
    include_str!("../wgsl/common/shade.wgsl"),
    "\n",
    include_str!("../wgsl/viewer.wgsl")
);

/// Every composed pipeline source, by file name.
pub fn sources() -> [(&'static str, &'static str); 6] {
    [
        ("vertex_ao.wgsl", VERTEX_AO),
        ("vertex_ao_vs.wgsl", VERTEX_AO_VS),
        ("cubemap_ao.wgsl", CUBEMAP_AO),
        ("grid_ao.wgsl", GRID_AO),
        ("preview.wgsl", PREVIEW),
        ("viewer.wgsl", VIEWER),
    ]
}

/// Workgroup size of the compute entry points (`@workgroup_size(64)`).
pub const WORKGROUP_SIZE: u32 = 64;

#[cfg(test)]
mod tests {
    use super::*;

    fn validate(name: &str, src: &str) -> naga::valid::ModuleInfo {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        // The capabilities of a WebGPU-level adapter: nothing optional, so
        // a shader that passes here runs on GL/llvmpipe and lavapipe too.
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)))
    }

    #[test]
    fn every_shader_parses_and_validates() {
        for (name, src) in sources() {
            validate(name, src);
        }
    }

    #[test]
    fn every_wgsl_file_is_used() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/wgsl");
        let mut files = Vec::new();
        for entry in std::fs::read_dir(dir)
            .unwrap()
            .chain(std::fs::read_dir(format!("{dir}/common")).unwrap())
        {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "wgsl") {
                files.push(std::fs::read_to_string(&path).unwrap());
            }
        }
        assert!(!files.is_empty());
        for text in files {
            assert!(
                sources().iter().any(|(_, src)| src.contains(text.trim())),
                "a .wgsl file under shaders/wgsl is in no pipeline"
            );
        }
    }

    #[test]
    fn vertex_ao_has_both_entry_points() {
        let module = naga::front::wgsl::parse_str(VERTEX_AO).unwrap();
        let names: Vec<&str> = module
            .entry_points
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(names, ["cs_main", "cs_sparse"]);
        for e in &module.entry_points {
            assert_eq!(e.workgroup_size, [WORKGROUP_SIZE, 1, 1]);
        }
    }

    /// The size naga computes for a WGSL struct.
    fn wgsl_size(src: &str, name: &str) -> u32 {
        let module = naga::front::wgsl::parse_str(src).unwrap();
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).unwrap();
        let (handle, _) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name}"));
        layouter[handle].size
    }

    #[test]
    fn the_rust_mirrors_have_the_wgsl_sizes() {
        use std::mem::size_of;
        assert_eq!(
            wgsl_size(PREVIEW, "Uniforms") as usize,
            size_of::<PreviewUniforms>()
        );
        assert_eq!(
            wgsl_size(VERTEX_AO, "Params") as usize,
            size_of::<VertexAoParams>()
        );
        assert_eq!(
            wgsl_size(VERTEX_AO, "BlockInfo") as usize,
            size_of::<BlockInfo>()
        );
        assert_eq!(
            wgsl_size(VERTEX_AO_VS, "VsParams") as usize,
            size_of::<VertexAoVsParams>()
        );
        assert_eq!(
            wgsl_size(CUBEMAP_AO, "Params") as usize,
            size_of::<CubemapAoParams>()
        );
        for (name, size) in [
            ("Params", size_of::<GridAoParams>()),
            ("PartInfo", size_of::<GridPartInfo>()),
            ("Receiver", size_of::<GridReceiver>()),
            ("PartPose", 4 * 32),
        ] {
            assert_eq!(wgsl_size(GRID_AO, name) as usize, size, "{name}");
        }
    }

    #[test]
    fn preview_has_its_entry_points() {
        let module = naga::front::wgsl::parse_str(PREVIEW).unwrap();
        let names: Vec<&str> = module
            .entry_points
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(names, ["vs_main", "fs_main"]);
    }
}
