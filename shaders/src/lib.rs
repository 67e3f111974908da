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
//! * [`TRACE`]: ray casting in compute, the estimators of core's CPU
//!   tracer with the same rays (`cs_trace`).
//! * [`TEXEL_AO`]: the texel methods' run-time AO per pixel
//!   (`texel_ao(uv)`: the basis textures weighted and summed), drawn over
//!   a whole atlas.
//! * [`PREVIEW`]: the preview raster (`vs_main`, `fs_main`; `vs_texel`,
//!   `fs_texel` for a texel model).
//! * [`CUBEMAP_AO_VS`], [`GRID_AO_VS`]: the lookups in a vertex shader
//!   (data in textures), for WebGL2.
//! * [`VIEWER_VERTEX`], [`VIEWER_GRID`], [`VIEWER_CUBEMAP`]: the
//!   dashboard's WebGL2 viewer per method family: GPU skinning, the
//!   method's vertex-stage lookup and the previews' shading, for naga's
//!   GLSL ES 3.00.
//!
//! The Rust mirrors of the uniforms and storage structs are in [`mirror`],
//! field for field with size assertions; [`export`] translates the
//! run-time evaluators for engines (GLSL, HLSL, MSL, SPIR-V).

pub mod bindings;
pub mod export;
pub mod mirror;

pub use mirror::{
    BlockInfo, CubemapAoParams, GridAoParams, GridPartInfo, GridReceiver, GtaoParams,
    PreviewUniforms, TexelProbe, TexelWeights, TraceParams, TracePoint, TraceScene, TraceTally,
    VertexAoParams, VertexAoVsParams,
};

/// Half-float decoding shared by the pipelines.
pub const COMMON_F16: &str = include_str!("../wgsl/common/f16.wgsl");

/// Composes WGSL files under `shaders/wgsl/` into one source, in order.
macro_rules! compose {
    ($($file:literal),+ $(,)?) => {
        concat!($(include_str!(concat!("../wgsl/", $file)), "\n"),+)
    };
}

/// The vertex-method evaluation shader, composed: [`COMMON_F16`] then
/// `vertex_ao.wgsl`.
pub const VERTEX_AO: &str = compose!("common/f16.wgsl", "vertex_ao.wgsl");

/// The vertex-method evaluation in a vertex shader (textures instead of
/// storage buffers, for WebGL2 and GLSL ES 3.00), composed: [`COMMON_F16`],
/// `common/vertex_ao_textures.wgsl`, `common/point_target.wgsl`, then
/// `vertex_ao_vs.wgsl` (the tests' point draw).
pub const VERTEX_AO_VS: &str = compose!(
    "common/f16.wgsl",
    "common/vertex_ao_textures.wgsl",
    "common/point_target.wgsl",
    "vertex_ao_vs.wgsl"
);

/// Texels per row of the vertex-stage evaluators' data textures (WebGL2's
/// smallest `MAX_TEXTURE_SIZE`).
pub const VS_TEXTURE_WIDTH: u32 = 2048;

/// The cubemap lookup shader, composed: [`COMMON_F16`],
/// `common/ground_texture.wgsl`, `common/cubemap_lookup.wgsl`, then
/// `cubemap_ao.wgsl`.
pub const CUBEMAP_AO: &str = compose!(
    "common/f16.wgsl",
    "common/ground_texture.wgsl",
    "common/cubemap_lookup.wgsl",
    "cubemap_ao.wgsl"
);

/// The cubemap lookup in a vertex shader (textures, for WebGL2), composed:
/// [`COMMON_F16`], `common/data_textures.wgsl`,
/// `common/ground_texture.wgsl`, `common/cubemap_lookup.wgsl`,
/// `common/cubemap_textures.wgsl`, `common/point_target.wgsl`, then
/// `cubemap_ao_vs.wgsl`.
pub const CUBEMAP_AO_VS: &str = compose!(
    "common/f16.wgsl",
    "common/data_textures.wgsl",
    "common/ground_texture.wgsl",
    "common/cubemap_lookup.wgsl",
    "common/cubemap_textures.wgsl",
    "common/point_target.wgsl",
    "cubemap_ao_vs.wgsl"
);

/// The grid lookup shader, composed: `common/grid_lookup.wgsl` then
/// `grid_ao.wgsl`.
pub const GRID_AO: &str = compose!("common/grid_lookup.wgsl", "grid_ao.wgsl");

/// The grid lookup in a vertex shader (textures, for WebGL2), composed:
/// `common/data_textures.wgsl`, `common/grid_lookup.wgsl`,
/// `common/grid_textures.wgsl`, `common/point_target.wgsl`, then
/// `grid_ao_vs.wgsl`.
pub const GRID_AO_VS: &str = compose!(
    "common/data_textures.wgsl",
    "common/grid_lookup.wgsl",
    "common/grid_textures.wgsl",
    "common/point_target.wgsl",
    "grid_ao_vs.wgsl"
);

/// The preview raster shader, composed: `common/shade.wgsl`,
/// `common/texel_ao.wgsl` then `preview.wgsl`.
pub const PREVIEW: &str = compose!("common/shade.wgsl", "common/texel_ao.wgsl", "preview.wgsl");

/// The texel methods' run-time AO (`texel_ao(uv)`, k texture fetches per
/// pixel) drawn over a whole atlas (`vs_main`, `fs_main`): the tests'
/// draw, and the file engines start from. Composed:
/// `common/texel_ao.wgsl` then `texel_ao.wgsl`.
pub const TEXEL_AO: &str = compose!("common/texel_ao.wgsl", "texel_ao.wgsl");

/// The most basis layers (weights) a texel model may have on the GPU
/// (`TEXEL_MAX_LAYERS` in common/texel_ao.wgsl).
pub const TEXEL_MAX_LAYERS: u32 = 256;

/// The screen-space baseline (GTAO) over a G-buffer: `gtao.wgsl`.
pub const GTAO: &str = compose!("gtao.wgsl");

/// The dashboard viewer's shader for a vertex-method asset (WebGL2 through
/// naga's GLSL ES 3.00, [`export::webgl_viewer`]): `common/shade.wgsl`,
/// `viewer.wgsl`, the vertex-stage evaluator and `viewer_vertex.wgsl`.
pub const VIEWER_VERTEX: &str = compose!(
    "common/shade.wgsl",
    "viewer.wgsl",
    "common/f16.wgsl",
    "common/vertex_ao_textures.wgsl",
    "viewer_vertex.wgsl"
);

/// The viewer's shader for a grid asset: `common/shade.wgsl`,
/// `viewer.wgsl`, the grid's vertex-stage lookup and `viewer_grid.wgsl`.
pub const VIEWER_GRID: &str = compose!(
    "common/shade.wgsl",
    "viewer.wgsl",
    "common/data_textures.wgsl",
    "common/ground_texture.wgsl",
    "common/grid_lookup.wgsl",
    "common/grid_textures.wgsl",
    "viewer_grid.wgsl"
);

/// The viewer's shader for a cubemap asset: `common/shade.wgsl`,
/// `viewer.wgsl`, the cubemap's vertex-stage lookup and
/// `viewer_cubemap.wgsl`.
pub const VIEWER_CUBEMAP: &str = compose!(
    "common/shade.wgsl",
    "viewer.wgsl",
    "common/f16.wgsl",
    "common/data_textures.wgsl",
    "common/ground_texture.wgsl",
    "common/cubemap_lookup.wgsl",
    "common/cubemap_textures.wgsl",
    "viewer_cubemap.wgsl"
);

/// Ray casting in compute, the CPU tracer's estimators (`cs_trace`):
/// `trace.wgsl`.
pub const TRACE: &str = compose!("trace.wgsl");

/// Every composed pipeline source, by file name.
pub fn sources() -> [(&'static str, &'static str); 13] {
    [
        ("texel_ao.wgsl", TEXEL_AO),
        ("trace.wgsl", TRACE),
        ("vertex_ao.wgsl", VERTEX_AO),
        ("vertex_ao_vs.wgsl", VERTEX_AO_VS),
        ("cubemap_ao.wgsl", CUBEMAP_AO),
        ("cubemap_ao_vs.wgsl", CUBEMAP_AO_VS),
        ("grid_ao.wgsl", GRID_AO),
        ("grid_ao_vs.wgsl", GRID_AO_VS),
        ("preview.wgsl", PREVIEW),
        ("gtao.wgsl", GTAO),
        ("viewer_vertex.wgsl", VIEWER_VERTEX),
        ("viewer_grid.wgsl", VIEWER_GRID),
        ("viewer_cubemap.wgsl", VIEWER_CUBEMAP),
    ]
}

/// Workgroup size of the compute entry points (`@workgroup_size(64)`).
pub const WORKGROUP_SIZE: u32 = 64;

/// Invocations that share a point's rays in `cs_trace` (`LANES` in
/// trace.wgsl).
pub const TRACE_LANES: u32 = 16;

/// Entries of `cs_trace`'s traversal stack (`STACK` in trace.wgsl): the
/// host leaves a deeper tree to the CPU.
pub const TRACE_STACK: u32 = 96;

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

    #[test]
    fn the_texel_layer_limit_is_the_hosts() {
        let module = naga::front::wgsl::parse_str(TEXEL_AO).unwrap();
        let (_, c) = module
            .constants
            .iter()
            .find(|(_, c)| c.name.as_deref() == Some("TEXEL_MAX_LAYERS"))
            .unwrap();
        assert!(matches!(
            module.global_expressions[c.init],
            naga::Expression::Literal(naga::Literal::U32(TEXEL_MAX_LAYERS))
        ));
        let zero: TexelWeights = bytemuck::Zeroable::zeroed();
        assert_eq!(zero.w.len() * 4, TEXEL_MAX_LAYERS as usize);
        let weights: Vec<f32> = (0..TEXEL_MAX_LAYERS).map(|k| k as f32).collect();
        let full = TexelWeights::new(&weights).unwrap();
        assert_eq!((full.count, full.w[3][2]), (TEXEL_MAX_LAYERS, 14.0));
        assert!(TexelWeights::new(&[0.0; TEXEL_MAX_LAYERS as usize + 1]).is_none());
    }

    #[test]
    fn the_tracers_constants_are_the_hosts() {
        let module = naga::front::wgsl::parse_str(TRACE).unwrap();
        let constant = |name: &str| {
            let (_, c) = module
                .constants
                .iter()
                .find(|(_, c)| c.name.as_deref() == Some(name))
                .unwrap_or_else(|| panic!("no constant {name}"));
            match module.global_expressions[c.init] {
                naga::Expression::Literal(naga::Literal::U32(v)) => v,
                ref other => panic!("{name}: {other:?}"),
            }
        };
        assert_eq!(constant("LANES"), TRACE_LANES);
        assert_eq!(constant("STACK"), TRACE_STACK);
        let entry = module.entry_points.iter().find(|e| e.name == "cs_trace");
        assert_eq!(entry.unwrap().workgroup_size, [WORKGROUP_SIZE, 1, 1]);
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
        assert_eq!(wgsl_size(GTAO, "Params") as usize, size_of::<GtaoParams>());
        assert_eq!(
            wgsl_size(TEXEL_AO, "TexelWeights") as usize,
            size_of::<TexelWeights>()
        );
        assert_eq!(
            wgsl_size(TEXEL_AO, "TexelProbe") as usize,
            size_of::<TexelProbe>()
        );
        for (name, size) in [
            ("Params", size_of::<GridAoParams>()),
            ("PartInfo", size_of::<GridPartInfo>()),
            ("Receiver", size_of::<GridReceiver>()),
            ("PartPose", 4 * 32),
        ] {
            assert_eq!(wgsl_size(GRID_AO, name) as usize, size, "{name}");
        }
        for (name, size) in [
            ("Params", size_of::<TraceParams>()),
            ("SceneInfo", size_of::<TraceScene>()),
            ("RayPoint", size_of::<TracePoint>()),
            ("Tally", size_of::<TraceTally>()),
        ] {
            assert_eq!(wgsl_size(TRACE, name) as usize, size, "{name}");
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
        assert_eq!(
            names,
            [
                "vs_main",
                "fs_main",
                "fs_gbuffer",
                "fs_screen_space",
                "vs_texel",
                "fs_texel",
                "fs_gbuffer_texel"
            ]
        );
    }
}
