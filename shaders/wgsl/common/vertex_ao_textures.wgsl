// The vertex methods' run-time AO in a vertex shader, for APIs without
// compute shaders or storage buffers (WebGL2, GLSL ES 3.00): the
// arithmetic of vertex_ao.wgsl term for term (the same sums in the same
// order, so the same bits), its arrays read from textures instead.
//
// Every array of vertex_ao.wgsl is an R32Uint texture `width` texels wide,
// element i at texel (i % width, i / width): `blocks` (8 words per block:
// rows, columns, coefficient offset, map offset, weight offset, 3 unused),
// `coefficients` (f16 two per word), `maps` (vertex-cluster maps; sparse:
// the V + 1 row offsets), `weights` (the f32 bits) and `sparse_rows` (u16
// two per word), bound at group 0, bindings 0 (VsParams) to 5. An engine
// calls `vertex_ao(vertex_index)` from its own vertex shader, as
// vertex_ao_vs.wgsl (the tests' point draw) and viewer.wgsl (the
// dashboard's viewer) do.
//
// Needs common/f16.wgsl.

struct VsParams {
    vertices: u32,
    blocks: u32,
    // 1: sparse (CSR) coefficients; 0: dense blocks.
    sparse: u32,
    // Texels per row of every data texture.
    width: u32,
    // The test target's size in pixels.
    target_width: u32,
    target_height: u32,
    _pad0: u32,
    _pad1: u32,
}

const VS_NO_MAP: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> vs_params: VsParams;
@group(0) @binding(1) var blocks_tex: texture_2d<u32>;
@group(0) @binding(2) var coefficients_tex: texture_2d<u32>;
@group(0) @binding(3) var maps_tex: texture_2d<u32>;
@group(0) @binding(4) var weights_tex: texture_2d<u32>;
@group(0) @binding(5) var sparse_rows_tex: texture_2d<u32>;

fn texel(i: u32) -> vec2<i32> {
    return vec2<i32>(i32(i % vs_params.width), i32(i / vs_params.width));
}

fn block_word(b: u32, k: u32) -> u32 {
    return textureLoad(blocks_tex, texel(8u * b + k), 0).x;
}

fn coefficient_at(e: u32) -> f32 {
    let word = textureLoad(coefficients_tex, texel(e >> 1u), 0).x;
    return f16_bits_to_f32(half_of(word, e));
}

fn map_at(i: u32) -> u32 {
    return textureLoad(maps_tex, texel(i), 0).x;
}

fn weight_at(i: u32) -> f32 {
    return bitcast<f32>(textureLoad(weights_tex, texel(i), 0).x);
}

fn sparse_row_at(e: u32) -> u32 {
    return half_of(textureLoad(sparse_rows_tex, texel(e >> 1u), 0).x, e);
}

// The AO of vertex v: vertex_ao.wgsl's cs_main, or cs_sparse.
fn vertex_ao(v: u32) -> f32 {
    var sum = 0.0;
    if (vs_params.sparse != 0u) {
        let end = map_at(v + 1u);
        for (var e = map_at(v); e < end; e = e + 1u) {
            sum = sum + weight_at(sparse_row_at(e)) * coefficient_at(e);
        }
    } else {
        for (var b = 0u; b < vs_params.blocks; b = b + 1u) {
            let rows = block_word(b, 0u);
            let columns = block_word(b, 1u);
            let coef_offset = block_word(b, 2u);
            let map_offset = block_word(b, 3u);
            let weight_offset = block_word(b, 4u);
            var column = v;
            if (map_offset != VS_NO_MAP) {
                column = map_at(map_offset + v);
            }
            for (var k = 0u; k < rows; k = k + 1u) {
                let w = weight_at(weight_offset + k);
                if (w != 0.0) {
                    sum = sum + w * coefficient_at(coef_offset + k * columns + column);
                }
            }
        }
    }
    return clamp(sum, 0.0, 1.0);
}

