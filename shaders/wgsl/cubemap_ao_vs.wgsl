// The cubemap lookup in a vertex shader (WebGL2, GLSL ES 3.00), drawn for
// the tests as vertex_ao_vs.wgsl is: point n (its xyz f32 bits at words
// 3n..3n+3 of the texture at binding 3) at pixel (n % target_width,
// n / target_width) of an R32Uint target, which receives its occlusion's
// bits at `params.phase` (on the ground plane with `params.on_ground`). An
// engine calls cubemap_occlusion(p, phase), or cubemap_ground_ao(p, phase)
// on its ground, from its own shaders with common/cubemap_textures.wgsl's
// bindings.
//
// Prepended at load time: common/f16.wgsl, common/data_textures.wgsl,
// common/ground_texture.wgsl, common/cubemap_lookup.wgsl,
// common/cubemap_textures.wgsl, common/point_target.wgsl.

@group(0) @binding(3) var cubemap_points: texture_2d<u32>;

fn point_float(i: u32) -> f32 {
    return bitcast<f32>(textureLoad(cubemap_points, data_texel(i), 0).x);
}

@vertex
fn vs_main(@builtin(vertex_index) n: u32) -> PointOut {
    let p = vec3<f32>(point_float(3u * n), point_float(3u * n + 1u), point_float(3u * n + 2u));
    let occlusion = cubemap_point(p, params.phase);
    return point_out(n, data_layout.target_width, data_layout.target_height, occlusion);
}
