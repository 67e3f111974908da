// Run-time lookup of Kroon's cubemaps over a batch of points in a compute
// shader: common/cubemap_lookup.wgsl's `cubemap_occlusion(p, phase)` (and
// on the ground plane `cubemap_ground_ao(p, phase)`, with the static
// ground) with the texels in a storage buffer. An engine uses them in its
// own shaders; cs_main evaluates a batch of points (what the tests and the
// previews run).
//
// Prepended at load time: common/f16.wgsl, common/ground_texture.wgsl,
// common/cubemap_lookup.wgsl.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> texels: array<vec4<u32>>;
// Points as packed xyz floats (a vertex buffer of vec3<f32>).
@group(0) @binding(2) var<storage, read> points: array<f32>;
@group(0) @binding(3) var<storage, read_write> occlusion: array<f32>;
// The static ground (common/ground_texture.wgsl's words).
@group(0) @binding(4) var<storage, read> ground_words: array<u32>;

fn ground_word(i: u32) -> u32 {
    return ground_words[i];
}

fn texel_at(layer: u32, i: u32, j: u32) -> vec4<u32> {
    let res = params.resolution;
    return texels[(layer * res + j) * res + i];
}

@compute @workgroup_size(64)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = id.y * params.row_stride + id.x;
    if (n >= params.points) {
        return;
    }
    let p = vec3<f32>(points[3u * n], points[3u * n + 1u], points[3u * n + 2u]);
    occlusion[n] = cubemap_point(p, params.phase);
}
