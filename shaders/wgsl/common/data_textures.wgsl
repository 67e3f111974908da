// How the vertex-stage lookups (cubemap_ao_vs.wgsl, grid_ao_vs.wgsl and
// the viewer) read arrays from R32Uint textures, for APIs without storage
// buffers (WebGL2, GLSL ES 3.00): word i of an array at texel
// (i % width, i / width) of its texture. `data_layout.width` is the same
// for every texture; `target_width` and `target_height` size the tests'
// point targets.

struct DataLayout {
    width: u32,
    target_width: u32,
    target_height: u32,
    _pad: u32,
}

fn data_texel(i: u32) -> vec2<i32> {
    return vec2<i32>(i32(i % data_layout.width), i32(i / data_layout.width));
}
