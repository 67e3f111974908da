// The viewer's model AO for the grid method: grid_ao at the skinned vertex
// with its normal (common/grid_textures.wgsl, bindings 0 to 4), a
// character's vertex on its own part with its static base's offset, the
// ground on no part with the offset of the base's ground texture there.
//
// `grid_receivers` (binding 5) holds the base's ground texture as
// common/ground_texture.wgsl reads it (its first word 0 without a base),
// then the character's vertex count V, then per vertex its part
// (0xffffffff for none) and its offset (f32 bits).
//
// Prepended at load time: common/data_textures.wgsl,
// common/ground_texture.wgsl, common/grid_lookup.wgsl,
// common/grid_textures.wgsl.

@group(0) @binding(5) var grid_receivers: texture_2d<u32>;

fn ground_word(i: u32) -> u32 {
    return textureLoad(grid_receivers, data_texel(i), 0).x;
}

fn model_ao(index: u32, world: vec3<f32>, normal: vec3<f32>, skinned: bool) -> f32 {
    if (skinned) {
        let n = ground_word(0u);
        let first = 6u + n * n + 2u * index;
        let own = ground_word(first);
        let offset = bitcast<f32>(ground_word(first + 1u));
        return grid_ao(world, normal, own, offset);
    }
    return grid_ao(world, normal, NO_PART, ground_offset(world));
}
