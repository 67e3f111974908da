// The lookup of Malmer et al.'s grids (aobake's grid method), shared by
// grid_ao.wgsl (storage buffers, compute) and grid_ao_vs.wgsl (textures,
// any shader stage, WebGL2): the
// occlusion that every rigid part casts on a receiver, from each part's 3D
// grid moved with the part. The GPU twin of
// aobake_core::method::grid::model::GridModel::occlusion, step for step:
//
// * the receiver goes into each part's grid space (grid_from_world; the
//   grid is [0, 1]^3); outside it the part casts nothing;
// * the eight nearest cell centres (at (i + 1/2)/n, clamped to the edge
//   cells) are blended trilinearly: ao' from the A byte (ao_grid = 2 ao'),
//   the cone axis from the RGB bytes (d = 2b/255 - 1, the part's bind
//   space, turned to world by world_from_bind);
// * with cones, every part casts T_clip(ao', d.n), its own part included
//   (section 5.1); without, another part casts min(1, ao_grid) and the
//   receiver's own part max(0, (ao_grid - 1)/2) (section 4.2);
// * the parts combine as 1 - prod(1 - a_i);
// * grid_ao adds the static base (aobake's product form): the combined
//   occlusion times the receiver's gain plus its offset, clamped
//   (runtime method::grid::base).
//
// Cells are one u32 each (RGBA8, R in the low byte), part after part, the
// bytes of the asset's RGBA section (or its OCCL bytes in A). With cones,
// T_clip follows the cells as pairs of f32 bits (occlusion, f),
// aperture-major.
//
// The including file declares `params: Params`, `fn cell_word(i: u32) ->
// u32`, `fn part_info(k: u32) -> PartInfo` and `fn part_pose(k: u32) ->
// PartPose`.

struct Params {
    parts: u32,
    points: u32,
    row_stride: u32,
    // 1 when the cones are baked.
    cones: u32,
    // T_clip's samples per axis.
    tclip_resolution: u32,
    // Index in `cells` of T_clip's first f32.
    tclip_offset: u32,
    // 1 when the asset has a static base.
    base: u32,
    // The bits of the base's ground gain (f32).
    ground_gain: u32,
}

struct PartInfo {
    // Cells per grid edge.
    resolution: u32,
    // Index in `cells` of the part's first cell.
    offset: u32,
    // The bits of the base's gain at the part's vertices (f32).
    gain: u32,
    _pad0: u32,
}

struct PartPose {
    grid_from_world: mat4x4<f32>,
    world_from_bind: mat4x4<f32>,
}

const NO_PART: u32 = 0xffffffffu;

fn tclip_at(a: u32, b: u32) -> vec2<f32> {
    let i = params.tclip_offset + 2u * (a * params.tclip_resolution + b);
    return vec2<f32>(bitcast<f32>(cell_word(i)), bitcast<f32>(cell_word(i + 1u)));
}

// T_clip's occlusion at aperture `alpha` (ao') and cos(beta), bilinear.
fn tclip_occlusion(alpha: f32, cos_beta: f32) -> f32 {
    let last = f32(params.tclip_resolution - 1u);
    let u = clamp(alpha, 0.0, 1.0) * last;
    let v = ((clamp(cos_beta, -1.0, 1.0) + 1.0) * 0.5) * last;
    let u0 = min(floor(u), last - 1.0);
    let v0 = min(floor(v), last - 1.0);
    let fu = u - u0;
    let fv = v - v0;
    let i = u32(u0);
    let j = u32(v0);
    let a = tclip_at(i, j).x;
    let top = a + (tclip_at(i, j + 1u).x - a) * fv;
    let c = tclip_at(i + 1u, j).x;
    let bottom = c + (tclip_at(i + 1u, j + 1u).x - c) * fv;
    return top + (bottom - top) * fu;
}

// The occlusion part k casts on a receiver at p with unit normal n.
fn part_occlusion(k: u32, p: vec3<f32>, n: vec3<f32>, own: bool) -> f32 {
    let pose = part_pose(k);
    let info = part_info(k);
    let g4 = pose.grid_from_world * vec4<f32>(p, 1.0);
    let g = g4.xyz;
    if (any(g < vec3<f32>(0.0)) || any(g > vec3<f32>(1.0))) {
        return 0.0;
    }
    let res = info.resolution;
    let last = f32(res - 1u);
    let s = clamp(g * f32(res) - 0.5, vec3<f32>(0.0), vec3<f32>(last));
    let i0 = min(floor(s), vec3<f32>(last - 1.0));
    let f = s - i0;
    let x = u32(i0.x);
    let y = u32(i0.y);
    let z = u32(i0.z);
    var fraction = 0.0;
    var axis = vec3<f32>(0.0);
    for (var dz = 0u; dz < 2u; dz++) {
        let wz = select(1.0 - f.z, f.z, dz == 1u);
        for (var dy = 0u; dy < 2u; dy++) {
            let wy = select(1.0 - f.y, f.y, dy == 1u);
            for (var dx = 0u; dx < 2u; dx++) {
                let wx = select(1.0 - f.x, f.x, dx == 1u);
                let w = wx * wy * wz;
                let cell = unpack4x8unorm(cell_word(info.offset + ((z + dz) * res + (y + dy)) * res + (x + dx)));
                fraction += w * cell.w;
                if (params.cones == 1u) {
                    axis += w * (cell.xyz * 2.0 - 1.0);
                }
            }
        }
    }
    let ao_grid = 2.0 * fraction;
    if (params.cones == 1u) {
        let world = (pose.world_from_bind * vec4<f32>(axis, 0.0)).xyz;
        let len = length(world);
        var d = vec3<f32>(0.0);
        if (len > 0.0) {
            d = world * (1.0 / len);
        }
        return tclip_occlusion(fraction, dot(d, n));
    }
    if (own) {
        return max((ao_grid - 1.0) * 0.5, 0.0);
    }
    return min(ao_grid, 1.0);
}

// The occlusion at receiver p with unit normal n on part `own` (NO_PART
// for a receiver of no part, such as the ground), over every part.
fn grid_occlusion(p: vec3<f32>, n: vec3<f32>, own: u32) -> f32 {
    var open = 1.0;
    for (var k = 0u; k < params.parts; k++) {
        open *= 1.0 - part_occlusion(k, p, n, k == own);
    }
    return 1.0 - open;
}


// The occlusion an engine shows at a vertex of the character or a point of
// the ground (GridModel::ao): with a static base, grid_occlusion times the
// gain of the receiver's part (the ground's for NO_PART) plus `offset` (a
// vertex's VOFS value, a ground point's bilinear GOFS value), clamped to
// [0, 1]; without, grid_occlusion alone. Any other surface (one the base
// knows nothing of) takes grid_occlusion alone.
fn grid_ao(p: vec3<f32>, n: vec3<f32>, own: u32, offset: f32) -> f32 {
    let g = grid_occlusion(p, n, own);
    if (params.base == 0u) {
        return g;
    }
    var gain = bitcast<f32>(params.ground_gain);
    if (own != NO_PART) {
        gain = bitcast<f32>(part_info(own).gain);
    }
    return clamp(gain * g + offset, 0.0, 1.0);
}
