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

struct Uniforms {
    clip_from_world: mat4x4<f32>,
    // xyz: the eye (world space).
    eye: vec4<f32>,
    // xyz: unit direction towards the key light; w: its intensity.
    light: vec4<f32>,
    // rgb: ambient radiance; w: the key light's wrap (0 = Lambert).
    ambient: vec4<f32>,
    // rgb: the surface's albedo.
    albedo: vec4<f32>,
    // rgb: the heat map's colour of no error; w: its saturating error.
    neutral: vec4<f32>,
    too_dark: vec4<f32>,
    too_bright: vec4<f32>,
    // xyz: the ground's centre; w: its half extent (it fades out there).
    ground: vec4<f32>,
    // rgb: the background, which the ground fades into.
    background: vec4<f32>,
    panel: u32,
    surface: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(3) model: f32,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(3) model: f32,
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = u.clip_from_world * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.truth = v.truth;
    out.model = v.model;
    return out;
}

fn heat(error: f32) -> vec3<f32> {
    let s = clamp(error / u.neutral.w, -1.0, 1.0);
    if s >= 0.0 {
        return mix(u.neutral.rgb, u.too_dark.rgb, s);
    }
    return mix(u.neutral.rgb, u.too_bright.rgb, -s);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    var n = normalize(in.normal);
    // Two-sided: a back face is lit as seen.
    if dot(n, u.eye.xyz - in.world) < 0.0 {
        n = -n;
    }
    let wrap = u.ambient.w;
    let key = u.light.w * max(0.0, (dot(n, u.light.xyz) + wrap) / (1.0 + wrap));
    let truth = clamp(in.truth, 0.0, 1.0);
    let model = clamp(in.model, 0.0, 1.0);
    var color: vec3<f32>;
    if u.panel == 2u {
        color = heat(model - truth) * (0.6 + 0.4 * key / max(u.light.w, 1e-6));
    } else {
        let ao = select(truth, model, u.panel == 1u);
        color = u.albedo.rgb * (u.ambient.rgb * (1.0 - ao) + vec3<f32>(key));
    }
    if u.surface == 1u {
        let r = length(in.world.xz - u.ground.xz) / u.ground.w;
        color = mix(color, u.background.rgb, smoothstep(0.5, 1.0, r));
    }
    return vec4<f32>(color, 1.0);
}
