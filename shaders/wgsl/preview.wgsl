// The preview raster: a character and its ground plane, shaded with
// ambient light × (1 − AO) plus a soft (wrapped) key light. One draw per
// surface (`surface`: 0 character, 1 ground) and per panel (`panel`):
//
//   0  the ray-traced AO (vertex attribute `truth`),
//   1  the model's AO (`model`, written by vertex_ao.wgsl on the GPU),
//   2  the error model − truth through the heat map of
//      aobake_core::bake::preview::HeatMap (too dark red, too bright blue),
//      lightly shaded so the shape stays readable.
//
// Lighting is linear; the target is an sRGB texture, so the hardware
// encodes on store and resolves multisamples in linear space.
// Mirrored field for field by aobake_shaders::PreviewUniforms.

// Prepended at load time: common/shade.wgsl (Uniforms, SurfaceIn, Shaded,
// shade).

@group(0) @binding(0) var<uniform> u: Uniforms;

@vertex
fn vs_main(v: SurfaceIn) -> Shaded {
    var out: Shaded;
    out.clip = u.clip_from_world * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.truth = v.truth;
    out.model = v.model;
    return out;
}

@fragment
fn fs_main(in: Shaded) -> @location(0) vec4<f32> {
    return vec4<f32>(shade(in.world, in.normal, in.truth, in.model), 1.0);
}
