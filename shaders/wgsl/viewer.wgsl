// The dashboard's 3D viewer (WebGL2, through naga's GLSL ES 3.00): a
// character skinned on the GPU and its ground plane, shaded as the
// previews are (common/shade.wgsl), with the model's AO from the method's
// run-time lookup in the vertex stage, its arrays in textures at bindings
// 0 to 5: `model_ao`, defined by viewer_vertex.wgsl (`vertex_ao(v)`),
// viewer_grid.wgsl (`grid_occlusion` at the skinned vertex, on its part)
// or viewer_cubemap.wgsl (`cubemap_occlusion` at the frame's phase). What
// an engine on WebGL2 does with an asset, end to end.
//
// Skinning is linear blend skinning as aobake_core's `Character::skin`
// does it: the palette matrices summed with their weights (zero weights
// skipped), positions through the sum, normals through its cofactor
// matrix (with the determinant's sign) and normalised. `skin` holds per
// vertex its `influences` joint indices, then as many weights (f32 bits);
// `palette` holds per joint its `world_from_bind` matrix, 16 f32 bits in
// column-major order. Both are R32Uint textures laid out as the AO's
// arrays are (element i at (i % width, i / width)).
//
// The target is the canvas, which is not sRGB: the fragment stage encodes
// the linear colour to sRGB itself (the previews let the hardware do it).
//
// Prepended at load time: common/shade.wgsl; then the family's lookup and
// viewer_{family}.wgsl.

// Texels per row of the skin and palette textures (WebGL2's smallest
// MAX_TEXTURE_SIZE).
const VIEWER_WIDTH: u32 = 2048u;

struct ViewerParams {
    // 1: skin by the palette; 0: draw as given (the ground).
    skinned: u32,
    // Joint influences per vertex in `skin`.
    influences: u32,
    // 1: the model's AO, model_ao(…); 0: the `model` attribute (the static
    // average, the truth, or none).
    model: u32,
    // A cubemap's phase of the clip's cycle at this frame.
    phase: f32,
}

@group(0) @binding(6) var<uniform> u: Uniforms;
@group(0) @binding(7) var<uniform> viewer: ViewerParams;
@group(0) @binding(8) var skin_tex: texture_2d<u32>;
@group(0) @binding(9) var palette_tex: texture_2d<u32>;

fn skin_word(i: u32) -> u32 {
    return textureLoad(skin_tex, viewer_texel(i), 0).x;
}

fn palette_at(i: u32) -> f32 {
    return bitcast<f32>(textureLoad(palette_tex, viewer_texel(i), 0).x);
}

// Word i of the skin and palette textures, VIEWER_WIDTH texels wide.
fn viewer_texel(i: u32) -> vec2<i32> {
    return vec2<i32>(i32(i % VIEWER_WIDTH), i32(i / VIEWER_WIDTH));
}

fn palette_matrix(j: u32) -> mat4x4<f32> {
    let b = 16u * j;
    return mat4x4<f32>(
        vec4<f32>(palette_at(b), palette_at(b + 1u), palette_at(b + 2u), palette_at(b + 3u)),
        vec4<f32>(palette_at(b + 4u), palette_at(b + 5u), palette_at(b + 6u), palette_at(b + 7u)),
        vec4<f32>(palette_at(b + 8u), palette_at(b + 9u), palette_at(b + 10u), palette_at(b + 11u)),
        vec4<f32>(palette_at(b + 12u), palette_at(b + 13u), palette_at(b + 14u), palette_at(b + 15u)),
    );
}

// The skinning matrix of vertex v: Σ w · palette[j] over its influences.
fn skin_matrix(v: u32) -> mat4x4<f32> {
    let k = viewer.influences;
    var m = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    for (var i = 0u; i < k; i = i + 1u) {
        let w = bitcast<f32>(skin_word(2u * k * v + k + i));
        if (w != 0.0) {
            m = m + palette_matrix(skin_word(2u * k * v + i)) * w;
        }
    }
    return m;
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32, in: SurfaceIn) -> Shaded {
    var world = in.position;
    var normal = in.normal;
    if (viewer.skinned != 0u) {
        let m = skin_matrix(index);
        world = (m * vec4<f32>(in.position, 1.0)).xyz;
        let l = mat3x3<f32>(m[0].xyz, m[1].xyz, m[2].xyz);
        let cofactor = mat3x3<f32>(cross(l[1], l[2]), cross(l[2], l[0]), cross(l[0], l[1]));
        let sign = select(1.0, -1.0, determinant(l) < 0.0);
        let n = cofactor * in.normal * sign;
        let length = length(n);
        normal = select(vec3<f32>(0.0), n / length, length > 0.0);
    }
    var out: Shaded;
    out.clip = u.clip_from_world * vec4<f32>(world, 1.0);
    out.world = world;
    out.normal = normal;
    out.truth = in.truth;
    out.model = in.model;
    if (viewer.model != 0u) {
        out.model = model_ao(index, world, normal, viewer.skinned != 0u);
    }
    return out;
}

fn srgb(c: vec3<f32>) -> vec3<f32> {
    let x = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    return select(1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055, 12.92 * x, x <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(in: Shaded) -> @location(0) vec4<f32> {
    return vec4<f32>(srgb(shade(in.world, in.normal, in.truth, in.model)), 1.0);
}
