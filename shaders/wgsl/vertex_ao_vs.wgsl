// vertex_ao_textures.wgsl's `vertex_ao(v)` drawn for the tests
// (common/point_target.wgsl): vertex v as a point at pixel
// (v % target_width, v / target_width) of an R32Uint target (the AO's
// bits), which is how the tests read it back.
//
// Prepended at load time: common/f16.wgsl, common/vertex_ao_textures.wgsl,
// common/point_target.wgsl.

@vertex
fn vs_main(@builtin(vertex_index) v: u32) -> PointOut {
    return point_out(v, vs_params.target_width, vs_params.target_height, vertex_ao(v));
}
