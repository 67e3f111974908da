// The viewer's model AO for the vertex methods: vertex_ao(v) of
// common/vertex_ao_textures.wgsl (bindings 0 to 5), the character only.
//
// Prepended at load time: common/f16.wgsl, common/vertex_ao_textures.wgsl.

fn model_ao(index: u32, world: vec3<f32>, normal: vec3<f32>, skinned: bool) -> f32 {
    return vertex_ao(index);
}
