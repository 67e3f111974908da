// The tests' read-back of a vertex-stage evaluator (vertex_ao_vs.wgsl,
// cubemap_ao_vs.wgsl, grid_ao_vs.wgsl): element n drawn as a point at
// pixel (n % target_width, n / target_width) of an R32Uint target, which
// receives its value's bits (R32Float is not renderable on every WebGL2
// or GL adapter).

struct PointOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) value: f32,
}

fn point_out(n: u32, target_width: u32, target_height: u32, value: f32) -> PointOut {
    let x = f32(n % target_width) + 0.5;
    let y = f32(n / target_width) + 0.5;
    var out: PointOut;
    out.position = vec4<f32>(2.0 * x / f32(target_width) - 1.0, 1.0 - 2.0 * y / f32(target_height), 0.0, 1.0);
    out.value = value;
    return out;
}

@fragment
fn fs_main(in: PointOut) -> @location(0) vec4<u32> {
    return vec4<u32>(bitcast<u32>(in.value), 0u, 0u, 1u);
}
