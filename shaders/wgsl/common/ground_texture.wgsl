// A static ground texture (runtime method::ground): words from
// `ground_word(i)`, which the including file declares: texels per side
// (0: no texture), then the f32 bits of the square's min x, min z and
// side, and of the gain, then each texel's offset (f32 bits, x fastest,
// rows along +z). GroundBase::offset step for step: bilinear between
// texel centres, clamped to the edge texels inside the square, 0 outside.

fn ground_texel(x: u32, z: u32, n: u32) -> f32 {
    return bitcast<f32>(ground_word(5u + z * n + x));
}

// The gain of the model's change on the ground.
fn ground_gain() -> f32 {
    return bitcast<f32>(ground_word(4u));
}

// The offset at ground point p (its x and z).
fn ground_offset(p: vec3<f32>) -> f32 {
    let n = ground_word(0u);
    if (n == 0u) {
        return 0.0;
    }
    let lo = vec2<f32>(bitcast<f32>(ground_word(1u)), bitcast<f32>(ground_word(2u)));
    let uv = (p.xz - lo) / bitcast<f32>(ground_word(3u));
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
