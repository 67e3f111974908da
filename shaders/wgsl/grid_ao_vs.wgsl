// The grid lookup in a vertex shader (WebGL2, GLSL ES 3.00), drawn for the
// tests as vertex_ao_vs.wgsl is: receiver n (8 words at 8n of the texture
// at binding 5: xyz position, its part's index, xyz unit normal, its
// static base's offset, as grid_ao.wgsl's Receiver) at pixel (n % target_width, n /
// target_width) of an R32Uint target, which receives its occlusion's
// bits. An engine calls grid_ao(p, n, own, offset) from its own shaders
// with common/grid_textures.wgsl's bindings.
//
// Prepended at load time: common/data_textures.wgsl,
// common/grid_lookup.wgsl, common/grid_textures.wgsl,
// common/point_target.wgsl.

@group(0) @binding(5) var grid_receivers: texture_2d<u32>;

fn receiver_word(i: u32) -> u32 {
    return textureLoad(grid_receivers, data_texel(i), 0).x;
}

@vertex
fn vs_main(@builtin(vertex_index) n: u32) -> PointOut {
    let b = 8u * n;
    let p = vec3<f32>(bitcast<f32>(receiver_word(b)), bitcast<f32>(receiver_word(b + 1u)), bitcast<f32>(receiver_word(b + 2u)));
    let normal = vec3<f32>(bitcast<f32>(receiver_word(b + 4u)), bitcast<f32>(receiver_word(b + 5u)), bitcast<f32>(receiver_word(b + 6u)));
    let occlusion = grid_ao(p, normal, receiver_word(b + 3u), bitcast<f32>(receiver_word(b + 7u)));
    return point_out(n, data_layout.target_width, data_layout.target_height, occlusion);
}
