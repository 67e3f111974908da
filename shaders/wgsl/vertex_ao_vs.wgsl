// vertex_ao_textures.wgsl's `vertex_ao(v)` drawn for the tests: vertex v
// as a point at pixel (v % target_width, v / target_width) of an R32Uint
// target (the AO's bits), which is how the tests read it back.
//
// Prepended at load time: common/f16.wgsl, common/vertex_ao_textures.wgsl.

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) ao: f32,
}

@vertex
fn vs_main(@builtin(vertex_index) v: u32) -> VsOut {
    let w = f32(vs_params.target_width);
    let h = f32(vs_params.target_height);
    let x = f32(v % vs_params.target_width) + 0.5;
    let y = f32(v / vs_params.target_width) + 0.5;
    var out: VsOut;
    out.position = vec4<f32>(2.0 * x / w - 1.0, 1.0 - 2.0 * y / h, 0.0, 1.0);
    out.ao = vertex_ao(v);
    return out;
}

// The AO's bits into an R32Uint target (R32Float is not renderable on
// every WebGL2 or GL adapter).
@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<u32> {
    return vec4<u32>(bitcast<u32>(in.ao), 0u, 0u, 1u);
}
