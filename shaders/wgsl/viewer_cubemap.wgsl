// The viewer's model AO for the cubemap methods: the occlusion the
// character casts at the ground's points at the frame's phase, with the
// static ground (common/cubemap_textures.wgsl, bindings 0 to 2 and 4).
//
// Prepended at load time: common/f16.wgsl, common/data_textures.wgsl,
// common/ground_texture.wgsl, common/cubemap_lookup.wgsl,
// common/cubemap_textures.wgsl.

fn model_ao(index: u32, world: vec3<f32>, normal: vec3<f32>, skinned: bool) -> f32 {
    return cubemap_ground_ao(world, viewer.phase);
}
