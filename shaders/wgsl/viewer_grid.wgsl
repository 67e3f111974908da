// The viewer's model AO for the grid method: grid_occlusion at the
// skinned vertex with its normal (common/grid_textures.wgsl, bindings 0 to
// 4), a character's vertex on its own part (`owners`, binding 5: a word
// per vertex, 0xffffffff for none), the ground on none.
//
// Prepended at load time: common/data_textures.wgsl,
// common/grid_lookup.wgsl, common/grid_textures.wgsl.

@group(0) @binding(5) var grid_owners: texture_2d<u32>;

fn model_ao(index: u32, world: vec3<f32>, normal: vec3<f32>, skinned: bool) -> f32 {
    var own = NO_PART;
    if (skinned) {
        own = textureLoad(grid_owners, data_texel(index), 0).x;
    }
    return grid_occlusion(world, normal, own);
}
