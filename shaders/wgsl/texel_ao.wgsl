// common/texel_ao.wgsl's `texel_ao(uv)` drawn over the whole atlas, for
// the tests and as an engine's starting point: a full-screen triangle
// into a target of the atlas's size (an R32Float one in the tests), whose
// fragment at pixel (x, y) writes the AO at texture coordinate
// ((x + 0.5 + offset.x) / width, (y + 0.5 + offset.y) / height): at
// offset 0 every texel centre, at others points between them, where the
// sampler filters.
//
// Prepended at load time: common/texel_ao.wgsl.

struct TexelProbe {
    // The target's size in pixels (the atlas's in texels).
    size: vec2<f32>,
    // Added to each pixel centre, in texels.
    offset: vec2<f32>,
}

@group(0) @binding(0) var<uniform> probe: TexelProbe;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // (-1, -1), (3, -1), (-1, 3): one triangle over the whole target.
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) pixel: vec4<f32>) -> @location(0) vec4<f32> {
    let uv = (pixel.xy + probe.offset) / probe.size;
    return vec4<f32>(texel_ao(uv), 0.0, 0.0, 1.0);
}
