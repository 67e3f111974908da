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
// Two more fragment stages serve the screen-space baseline (gtao.wgsl):
// `fs_gbuffer` writes the G-buffer it reads (single-sampled), and
// `fs_screen_space` shades a panel with its per-pixel occlusion (drawn
// with `panel` 1, the AO taken from `screen` instead of `model`).
//
// A texel model draws the character through `vs_texel` with the atlas's
// texture coordinate per vertex: `fs_texel` and `fs_gbuffer_texel` take
// the model's AO per pixel from its basis textures (texel_ao.wgsl), and
// the truth panel's from `texel_truth`, the ray-traced AO at the atlas's
// texels (dilated as the basis is); the G-buffer keeps the per-vertex
// truth, so the per-vertex floor is judged as for every model.
//
// Lighting is linear; the target is an sRGB texture, so the hardware
// encodes on store and resolves multisamples in linear space.
// Mirrored field for field by aobake_shaders::PreviewUniforms.

// Prepended at load time: common/shade.wgsl (Uniforms, SurfaceIn, Shaded,
// shade), common/texel_ao.wgsl (texel_ao, bindings 3 to 5).

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

// The G-buffer of a frame in integer targets (which every adapter can
// render to, unlike float ones): the world position's f32 bits and a word
// with the surface (low 2 bits: 1 character, 2 ground) and the model's AO
// in 20-bit fixed point above them; the interpolated normal's and
// ray-traced AO's f32 bits.
struct GBuffer {
    @location(0) position: vec4<u32>,
    @location(1) normal: vec4<u32>,
}

fn gbuffer(world: vec3<f32>, normal: vec3<f32>, truth: f32, model_ao: f32) -> GBuffer {
    var out: GBuffer;
    let model = u32(clamp(model_ao, 0.0, 1.0) * 1048575.0 + 0.5);
    out.position = vec4<u32>(bitcast<vec3<u32>>(world), (model << 2u) | (u.surface + 1u));
    out.normal = vec4<u32>(bitcast<vec3<u32>>(normal), bitcast<u32>(truth));
    return out;
}

@fragment
fn fs_gbuffer(in: Shaded) -> GBuffer {
    return gbuffer(in.world, in.normal, in.truth, in.model);
}

// The screen-space occlusion per pixel (gtao.wgsl's output) and the
// target's width.
@group(0) @binding(1) var<storage, read> screen: array<f32>;
@group(0) @binding(2) var<uniform> screen_width: vec4<u32>;

@fragment
fn fs_screen_space(in: Shaded) -> @location(0) vec4<f32> {
    let pixel = vec2<u32>(in.clip.xy);
    // Negative where the G-buffer's one sample missed the surface (an
    // edge sample of the multisampled panel): open.
    let ao = max(screen[pixel.y * screen_width.x + pixel.x], 0.0);
    return vec4<f32>(shade(in.world, in.normal, in.truth, ao), 1.0);
}

// A texel model's character: SurfaceIn with the atlas's UV.
struct TexelSurfaceIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(3) model: f32,
    @location(4) uv: vec2<f32>,
}

struct TexelShaded {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(4) uv: vec2<f32>,
}

// The ray-traced AO at the atlas's texels, dilated (sampled with
// texel_sampler).
@group(0) @binding(6) var texel_truth: texture_2d<f32>;

@vertex
fn vs_texel(v: TexelSurfaceIn) -> TexelShaded {
    var out: TexelShaded;
    out.clip = u.clip_from_world * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.truth = v.truth;
    out.uv = v.uv;
    return out;
}

@fragment
fn fs_texel(in: TexelShaded) -> @location(0) vec4<f32> {
    let truth = textureSample(texel_truth, texel_sampler, in.uv).x;
    return vec4<f32>(shade(in.world, in.normal, truth, texel_ao(in.uv)), 1.0);
}

@fragment
fn fs_gbuffer_texel(in: TexelShaded) -> GBuffer {
    return gbuffer(in.world, in.normal, in.truth, texel_ao(in.uv));
}
