// Screen-space ambient occlusion as engines compute it at run time: GTAO
// (Jimenez et al. 2016, "Practical Realtime Strategies for Accurate
// Indirect Occlusion"), from a frame's G-buffer (preview.wgsl's
// fs_gbuffer: world position and surface per pixel, the shading normal,
// in integer textures).
// The previews' baseline: what a studio gets without a bake.
//
// Per pixel, `slices` screen directions evenly spread over half a turn (no
// per-pixel noise, so no denoiser is needed and the image is
// deterministic); along each, `steps` samples on both sides out to the
// world-space `radius` (denser near the pixel), each raising that side's
// horizon unless it lies beyond the radius (faded out over its last
// `falloff` fraction). The cosine-weighted visibility between the two
// horizons, clamped to the normal's hemisphere, is integrated exactly per
// slice, weighted by the projected normal's length and averaged over the
// slices (the paper's Eq. 10; an open surface gets exactly 1). Only what is on screen occludes: that is the baseline's nature.
//
// Output: the occlusion 1 − visibility per pixel, row-major, and -1 where
// no surface is.

struct Params {
    // View space (x right, y up, looking down −z) from world space.
    view_from_world: mat4x4<f32>,
    // The eye (world space).
    eye: vec4<f32>,
    width: u32,
    height: u32,
    slices: u32,
    steps: u32,
    // Occluders farther than this from the pixel (world units) count not.
    radius: f32,
    // Pixels per world unit at view depth 1: (height / 2) / tan(fov_y / 2).
    focal: f32,
    // The fraction of the radius over which an occluder fades out.
    falloff: f32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// xyz: the world position's f32 bits; w's low 2 bits: 0 none,
// 1 character, 2 ground.
@group(0) @binding(1) var positions: texture_2d<u32>;
// The bits of f32: xyz the interpolated normal (world space).
@group(0) @binding(2) var normals: texture_2d<u32>;
@group(0) @binding(3) var<storage, read_write> occlusion: array<f32>;

const PI: f32 = 3.14159265358979;
const HALF_PI: f32 = 1.57079632679490;

fn view_point(world: vec3<f32>) -> vec3<f32> {
    return (params.view_from_world * vec4<f32>(world, 1.0)).xyz;
}

// The horizon cosine of one side of a slice: the highest of its samples,
// starting from the normal's tangent plane (`low`).
fn horizon(pixel: vec2<f32>, offset: vec2<f32>, p: vec3<f32>, v: vec3<f32>, low: f32) -> f32 {
    var best = low;
    let size = vec2<f32>(f32(params.width), f32(params.height));
    let fade_from = params.radius * (1.0 - params.falloff);
    let fade = max(params.radius * params.falloff, 1e-6);
    for (var k = 0u; k < params.steps; k++) {
        // Quadratically spread, at least one pixel out.
        let t = (f32(k) + 0.5) / f32(params.steps);
        let at = pixel + offset * (t * t) + normalize(offset) * 1.0;
        if any(at < vec2<f32>(0.0)) || any(at >= size) {
            break;
        }
        let texel = textureLoad(positions, vec2<i32>(at), 0);
        if (texel.w & 3u) == 0u {
            continue;
        }
        let d = view_point(bitcast<vec3<f32>>(texel.xyz)) - p;
        let dist = length(d);
        if dist < 1e-6 {
            continue;
        }
        let weight = clamp(1.0 - (dist - fade_from) / fade, 0.0, 1.0);
        best = max(best, mix(low, dot(d / dist, v), weight));
    }
    return best;
}

@compute @workgroup_size(8, 8)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let out = id.y * params.width + id.x;
    let texel = textureLoad(positions, vec2<i32>(id.xy), 0);
    if (texel.w & 3u) == 0u {
        occlusion[out] = -1.0;
        return;
    }
    let world = bitcast<vec3<f32>>(texel.xyz);
    let p = view_point(world);
    var wn = normalize(bitcast<vec3<f32>>(textureLoad(normals, vec2<i32>(id.xy), 0).xyz));
    if dot(wn, params.eye.xyz - world) < 0.0 {
        wn = -wn;
    }
    let n_view = normalize((params.view_from_world * vec4<f32>(wn, 0.0)).xyz);
    let v = normalize(-p);
    let pixel = vec2<f32>(id.xy) + vec2<f32>(0.5);
    let radius_px = params.radius * params.focal / max(-p.z, 1e-6);
    var visibility = 0.0;
    for (var s = 0u; s < params.slices; s++) {
        let phi = (f32(s) + 0.5) / f32(params.slices) * PI;
        let dir = vec3<f32>(cos(phi), sin(phi), 0.0);
        // Screen y grows downwards, view y upwards.
        let offset = vec2<f32>(dir.x, -dir.y) * radius_px;
        let ortho = dir - dot(dir, v) * v;
        let axis = normalize(cross(ortho, v));
        let projected = n_view - axis * dot(n_view, axis);
        let length_n = length(projected);
        if length_n < 1e-6 {
            // The normal lies along the slice's axis: the slice sees
            // nothing of the hemisphere's weight.
            continue;
        }
        let cos_n = clamp(dot(projected, v) / length_n, -1.0, 1.0);
        let n = sign(dot(ortho, projected)) * acos(cos_n);
        let c0 = horizon(pixel, offset, p, v, cos(n + HALF_PI));
        let c1 = horizon(pixel, -offset, p, v, cos(n - HALF_PI));
        // h1 towards +dir, h0 towards −dir, within the normal's hemisphere.
        let h1 = n + clamp(acos(clamp(c0, -1.0, 1.0)) - n, -HALF_PI, HALF_PI);
        let h0 = n + clamp(-acos(clamp(c1, -1.0, 1.0)) - n, -HALF_PI, HALF_PI);
        let arc0 = 0.25 * (cos_n + 2.0 * h0 * sin(n) - cos(2.0 * h0 - n));
        let arc1 = 0.25 * (cos_n + 2.0 * h1 * sin(n) - cos(2.0 * h1 - n));
        visibility += length_n * (arc0 + arc1);
    }
    // The mean over slices of the half-turn integral (open: exactly 1).
    occlusion[out] = clamp(1.0 - visibility / f32(params.slices), 0.0, 1.0);
}
