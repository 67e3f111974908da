// The texel methods' run-time AO (texel-linear; docs/methods/texel.md):
// per pixel, the pose's weights times the model's basis textures sampled
// at the atlas's texture coordinate, summed and clamped to the range of
// AO:
//
//   ao(uv) = clamp(Σ_k w[k] · basis_k(uv), 0, 1)
//
// `texel_basis` holds one layer per weight, in weight order: coefficient
// row k of the asset scattered into the atlas and dilated past the charts'
// borders (aobake_runtime's TexelModel::basis), so that bilinear filtering
// and mipmaps read chart values only. The weights are computed once per
// pose on the CPU, exactly as the vertex methods' (aobake-runtime's
// Model::weights; the C ABI's aobake_vertex_ao_weights on the handle
// aobake_texel_pose gives). Filtering is linear, so
// sampling each layer and summing is the sum's texture sampled. Per pixel:
// k texture fetches and k multiply-adds.
//
// Bindings (group 0; an engine renumbers them freely):
//   3  texel_basis    texture_2d_array<f32>, one layer per weight
//                      (R16Float: filterable everywhere, WebGL2 included)
//   4  texel_sampler  sampler: linear, clamp to edge
//   5  texel_weights  uniform TexelWeights (1,040 bytes)

// The most layers (weights): WebGPU's and WebGL2's least
// maxTextureArrayLayers.
const TEXEL_MAX_LAYERS: u32 = 256u;

// Mirrored field for field by aobake_shaders::TexelWeights.
struct TexelWeights {
    // Layers (weights) in use, at most TEXEL_MAX_LAYERS.
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // Weight k is w[k / 4][k % 4].
    w: array<vec4<f32>, 64>,
}

@group(0) @binding(3) var texel_basis: texture_2d_array<f32>;
@group(0) @binding(4) var texel_sampler: sampler;
@group(0) @binding(5) var<uniform> texel_weights: TexelWeights;

// The AO at texture coordinate `uv` of the atlas (a fragment stage's: the
// sampler picks the mip level from the derivatives).
fn texel_ao(uv: vec2<f32>) -> f32 {
    var sum = 0.0;
    let count = min(texel_weights.count, TEXEL_MAX_LAYERS);
    for (var k = 0u; k < count; k = k + 1u) {
        let w = texel_weights.w[k >> 2u][k & 3u];
        sum = sum + w * textureSample(texel_basis, texel_sampler, uv, k).x;
    }
    return clamp(sum, 0.0, 1.0);
}
