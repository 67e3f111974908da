// Kroon's cubemaps read from textures (common/data_textures.wgsl) for
// common/cubemap_lookup.wgsl: `params` at binding 0, the texels at
// binding 1 (four words a texel, in cubemap_ao.wgsl's order), the data
// layout at binding 2, the static ground's words
// (common/ground_texture.wgsl) at binding 4.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var cubemap_texels: texture_2d<u32>;
@group(0) @binding(2) var<uniform> data_layout: DataLayout;
@group(0) @binding(4) var cubemap_ground: texture_2d<u32>;

fn ground_word(i: u32) -> u32 {
    return textureLoad(cubemap_ground, data_texel(i), 0).x;
}

fn texel_word(i: u32) -> u32 {
    return textureLoad(cubemap_texels, data_texel(i), 0).x;
}

fn texel_at(layer: u32, i: u32, j: u32) -> vec4<u32> {
    let res = params.resolution;
    let w = 4u * ((layer * res + j) * res + i);
    return vec4<u32>(texel_word(w), texel_word(w + 1u), texel_word(w + 2u), texel_word(w + 3u));
}
