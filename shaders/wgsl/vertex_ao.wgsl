// Run-time per-vertex AO of aobake's vertex methods (static-average,
// vertex-linear, vertex-clustered): the linear form of
// aobake_core::model::LinearForm, one invocation per vertex.
//
//   ao[v] = clamp(Σ_b Σ_k w_b[k] · C_b[k, col_b(v)], 0, 1)
//
// with col_b(v) = v, or map_b[v] for a block whose columns are vertex
// clusters. The per-pose weights w are computed once per pose on the CPU
// (joint angles, or Kirk & Arikan's blended projections); coefficients are
// f16, two per u32. `cs_sparse` evaluates vertex-linear's sparse (CSR)
// coefficients. See docs/asset-format.md.
//
// Prepended at load time: common/f16.wgsl.

struct Params {
    vertices: u32,
    blocks: u32,
    // Vertices per row of the dispatch grid (workgroups in x × 64).
    row_stride: u32,
    _pad: u32,
}

struct BlockInfo {
    rows: u32,
    columns: u32,
    // Offset of the block's first coefficient, in f16 elements.
    coef_offset: u32,
    // Offset of the block's map in `maps`, or 0xffffffff for none.
    map_offset: u32,
    // Offset of the block's first weight in `weights`.
    weight_offset: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

const NO_MAP: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> blocks: array<BlockInfo>;
@group(0) @binding(2) var<storage, read> coefficients: array<u32>;
// Dense: vertex-cluster maps. Sparse: the V + 1 row offsets.
@group(0) @binding(3) var<storage, read> maps: array<u32>;
@group(0) @binding(4) var<storage, read> weights: array<f32>;
@group(0) @binding(5) var<storage, read_write> ao: array<f32>;
// Sparse only: the weight index of each coefficient, u16 two per word.
@group(0) @binding(6) var<storage, read> sparse_rows: array<u32>;

fn coefficient(e: u32) -> f32 {
    return f16_bits_to_f32(half_of(coefficients[e >> 1u], e));
}

fn vertex_index(gid: vec3<u32>) -> u32 {
    return gid.y * params.row_stride + gid.x;
}

@compute @workgroup_size(64)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = vertex_index(gid);
    if (v >= params.vertices) {
        return;
    }
    var sum = 0.0;
    for (var b = 0u; b < params.blocks; b = b + 1u) {
        let block = blocks[b];
        var column = v;
        if (block.map_offset != NO_MAP) {
            column = maps[block.map_offset + v];
        }
        for (var k = 0u; k < block.rows; k = k + 1u) {
            let w = weights[block.weight_offset + k];
            if (w != 0.0) {
                sum = sum + w * coefficient(block.coef_offset + k * block.columns + column);
            }
        }
    }
    ao[v] = clamp(sum, 0.0, 1.0);
}

@compute @workgroup_size(64)
fn cs_sparse(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = vertex_index(gid);
    if (v >= params.vertices) {
        return;
    }
    var sum = 0.0;
    for (var e = maps[v]; e < maps[v + 1u]; e = e + 1u) {
        let row = half_of(sparse_rows[e >> 1u], e);
        sum = sum + weights[row] * coefficient(e);
    }
    ao[v] = clamp(sum, 0.0, 1.0);
}
