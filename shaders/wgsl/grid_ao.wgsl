// Run-time lookup of Malmer et al.'s grids over a batch of receivers in a
// compute shader: common/grid_lookup.wgsl's `grid_ao(p, n, own, offset)`
// with the grids in storage buffers. An engine calls grid_ao in its own
// shaders; cs_main evaluates a batch of receivers (what the tests and the
// previews run).
//
// Prepended at load time: common/grid_lookup.wgsl.

// A receiver: xyz its position, w the bits of its part's index (none:
// 0xffffffff); then xyz its unit normal, w its static base's offset.
struct Receiver {
    position: vec4<f32>,
    normal: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> infos: array<PartInfo>;
@group(0) @binding(2) var<storage, read> cells: array<u32>;
@group(0) @binding(3) var<storage, read> poses: array<PartPose>;
@group(0) @binding(4) var<storage, read> receivers: array<Receiver>;
@group(0) @binding(5) var<storage, read_write> occlusion: array<f32>;

fn cell_word(i: u32) -> u32 {
    return cells[i];
}

fn part_info(k: u32) -> PartInfo {
    return infos[k];
}

fn part_pose(k: u32) -> PartPose {
    return poses[k];
}

@compute @workgroup_size(64)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.y * params.row_stride + id.x;
    if (i >= params.points) {
        return;
    }
    let r = receivers[i];
    occlusion[i] = grid_ao(r.position.xyz, r.normal.xyz, bitcast<u32>(r.position.w), r.normal.w);
}
