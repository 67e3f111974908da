// The viewer's model AO for the grid method: grid_ao at the skinned vertex
// with its normal (common/grid_textures.wgsl, bindings 0 to 4), a
// character's vertex on its own part with its static base's offset, the
// ground on no part with the offset of the base's ground texture there.
//
// `grid_receivers` (binding 5) holds: the ground square (min x, min z,
// side as f32 bits, then texels per side, 0 without a base), the
// character's vertex count V, per vertex its part (0xffffffff for none)
// and its offset (f32 bits), then the ground texels' offsets (f32 bits, x
// fastest). The ground's offset is looked up as the runtime's
// GroundBase::offset does: bilinear between texel centres, clamped to the
// edge texels inside the square, 0 outside it.
//
// Prepended at load time: common/data_textures.wgsl,
// common/grid_lookup.wgsl, common/grid_textures.wgsl.

@group(0) @binding(5) var grid_receivers: texture_2d<u32>;

fn receiver_word(i: u32) -> u32 {
    return textureLoad(grid_receivers, data_texel(i), 0).x;
}

fn ground_texel(x: u32, z: u32, n: u32) -> f32 {
    let first = 5u + 2u * receiver_word(4u);
    return bitcast<f32>(receiver_word(first + z * n + x));
}

fn ground_offset(p: vec3<f32>) -> f32 {
    let n = receiver_word(3u);
    if (n == 0u) {
        return 0.0;
    }
    let lo = vec2<f32>(bitcast<f32>(receiver_word(0u)), bitcast<f32>(receiver_word(1u)));
    let uv = (p.xz - lo) / bitcast<f32>(receiver_word(2u));
    if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0))) {
        return 0.0;
    }
    let last = f32(n - 1u);
    let s = clamp(uv * f32(n) - 0.5, vec2<f32>(0.0), vec2<f32>(last));
    let i0 = min(floor(s), vec2<f32>(max(last - 1.0, 0.0)));
    let f = s - i0;
    let x = u32(i0.x);
    let z = u32(i0.y);
    let x1 = min(x + 1u, n - 1u);
    let z1 = min(z + 1u, n - 1u);
    let a = ground_texel(x, z, n);
    let near = a + (ground_texel(x1, z, n) - a) * f.x;
    let b = ground_texel(x, z1, n);
    let far = b + (ground_texel(x1, z1, n) - b) * f.x;
    return near + (far - near) * f.y;
}

fn model_ao(index: u32, world: vec3<f32>, normal: vec3<f32>, skinned: bool) -> f32 {
    if (skinned) {
        let own = receiver_word(5u + 2u * index);
        let offset = bitcast<f32>(receiver_word(6u + 2u * index));
        return grid_ao(world, normal, own, offset);
    }
    return grid_ao(world, normal, NO_PART, ground_offset(world));
}
