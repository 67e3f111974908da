// The preview's shading, shared by preview.wgsl (wgpu) and viewer.wgsl
// (the dashboard's WebGL2 viewer, through naga's GLSL ES 3.00): ambient
// light × (1 − AO) plus a soft (wrapped) key light, or the error's heat
// map. The including file declares `u: Uniforms`; `SurfaceIn` and `Shaded`
// are both pipelines' vertex input and output.
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

// A surface's vertex as the previews and the viewer draw it: `truth` the
// ray-traced AO, `model` the AO shown for the model (the viewer's vertex
// stage may look it up instead).
struct SurfaceIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(3) model: f32,
}

// What the fragment stage shades.
struct Shaded {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) truth: f32,
    @location(3) model: f32,
}

fn heat(error: f32) -> vec3<f32> {
    let s = clamp(error / u.neutral.w, -1.0, 1.0);
    if s >= 0.0 {
        return mix(u.neutral.rgb, u.too_dark.rgb, s);
    }
    return mix(u.neutral.rgb, u.too_bright.rgb, -s);
}

// The linear colour of a surface point: `panel` 0 shades with `truth`, 1
// with `model`, 2 shows `model − truth` through the heat map, lightly
// shaded so the shape stays readable; the ground (`surface` 1) fades into
// the background at its edge.
fn shade(world: vec3<f32>, normal: vec3<f32>, truth_ao: f32, model_ao: f32) -> vec3<f32> {
    var n = normalize(normal);
    // Two-sided: a back face is lit as seen.
    if dot(n, u.eye.xyz - world) < 0.0 {
        n = -n;
    }
    let wrap = u.ambient.w;
    let key = u.light.w * max(0.0, (dot(n, u.light.xyz) + wrap) / (1.0 + wrap));
    let truth = clamp(truth_ao, 0.0, 1.0);
    let model = clamp(model_ao, 0.0, 1.0);
    var color: vec3<f32>;
    if u.panel == 2u {
        color = heat(model - truth) * (0.6 + 0.4 * key / max(u.light.w, 1e-6));
    } else {
        let ao = select(truth, model, u.panel == 1u);
        color = u.albedo.rgb * (u.ambient.rgb * (1.0 - ao) + vec3<f32>(key));
    }
    if u.surface == 1u {
        let r = length(world.xz - u.ground.xz) / u.ground.w;
        color = mix(color, u.background.rgb, smoothstep(0.5, 1.0, r));
    }
    return color;
}
