// Malmer et al.'s grids read from textures (common/data_textures.wgsl) for
// common/grid_lookup.wgsl: `params` at binding 0; the parts' infos (four
// words a part) at binding 1, the cells (and T_clip) at binding 2, the
// parts' poses (32 words a part: grid_from_world then world_from_bind,
// column-major f32 bits) at binding 3; the data layout at binding 4.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var grid_infos: texture_2d<u32>;
@group(0) @binding(2) var grid_cells: texture_2d<u32>;
@group(0) @binding(3) var grid_poses: texture_2d<u32>;
@group(0) @binding(4) var<uniform> data_layout: DataLayout;

fn cell_word(i: u32) -> u32 {
    return textureLoad(grid_cells, data_texel(i), 0).x;
}

fn info_word(i: u32) -> u32 {
    return textureLoad(grid_infos, data_texel(i), 0).x;
}

fn pose_float(i: u32) -> f32 {
    return bitcast<f32>(textureLoad(grid_poses, data_texel(i), 0).x);
}

fn part_info(k: u32) -> PartInfo {
    return PartInfo(info_word(4u * k), info_word(4u * k + 1u), info_word(4u * k + 2u), 0u);
}

fn pose_matrix(at: u32) -> mat4x4<f32> {
    return mat4x4<f32>(
        vec4<f32>(pose_float(at), pose_float(at + 1u), pose_float(at + 2u), pose_float(at + 3u)),
        vec4<f32>(pose_float(at + 4u), pose_float(at + 5u), pose_float(at + 6u), pose_float(at + 7u)),
        vec4<f32>(pose_float(at + 8u), pose_float(at + 9u), pose_float(at + 10u), pose_float(at + 11u)),
        vec4<f32>(pose_float(at + 12u), pose_float(at + 13u), pose_float(at + 14u), pose_float(at + 15u)),
    );
}

fn part_pose(k: u32) -> PartPose {
    return PartPose(pose_matrix(32u * k), pose_matrix(32u * k + 16u));
}
