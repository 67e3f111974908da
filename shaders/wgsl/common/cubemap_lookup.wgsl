// The lookup of Kroon's cubemaps (aobake's cubemap-discrete and
// cubemap-continuous), shared by cubemap_ao.wgsl (storage buffers, compute)
// and cubemap_ao_vs.wgsl (textures, any shader stage, WebGL2): the
// occlusion a character casts at points in space at one phase of its
// cycle. The GPU twin of
// aobake_runtime::method::cubemap::model::CubemapModel::occlusion, step for
// step:
//
// * the point's direction and normalised radius through the spheroid;
// * the direction picks a face and texel coordinates; the four nearest
//   texel centres (clamped to the face) are decoded and blended
//   bilinearly: decoded values are blended, never coefficients;
// * the radius gives a fractional shell k; inside the innermost shell its
//   value holds, beyond the outermost the occlusion fades to 0 over one
//   shell spacing;
// * time is phase × S_t samples, decoded continuously and cyclically.
//
// Texels are 16 bytes (a vec4<u32>, little-endian bytes), layer-major:
// index ((layer · res + j) · res + i) with layer = cubemap · 6 + face,
// the same bytes an engine uploads as a cube-map array of RGBA32Uint. The
// discrete encoding has one cubemap per shell; the continuous layouts
// spread a texel's 64 bytes over four cubemaps (bytes 16c..16c+16 in
// cubemap c).
//
// The including file declares `params: Params` and
// `fn texel_at(layer: u32, i: u32, j: u32) -> vec4<u32>`. Needs
// common/f16.wgsl.

struct Params {
    // xyz: the spheroid's centre; w: the outer scaling.
    centre: vec4<f32>,
    // xyz: the spheroid's radii; w: the inner scaling.
    radii: vec4<f32>,
    resolution: u32,
    shells: u32,
    times: u32,
    // 0 discrete, 1 continuous (cosine layout), 2 continuous (Kroon's
    // thirds layout).
    encoding: u32,
    points: u32,
    phase: f32,
    // Points per row of the dispatch grid (workgroups in x × 64).
    row_stride: u32,
    // 1: the points are on the ground plane (cubemap_ground_ao); 0:
    // anywhere (cubemap_occlusion).
    on_ground: u32,
}

const PI: f32 = 3.14159265358979;

// Byte `b` (0..16) of a texel.
fn texel_byte(t: vec4<u32>, b: u32) -> u32 {
    return (t[b / 4u] >> ((b % 4u) * 8u)) & 0xffu;
}

// x mod n for n > 0, into [0, n).
fn wrap(x: f32, n: f32) -> f32 {
    return x - n * floor(x / n);
}

// One texel's time curve (16 bytes) at time tau (samples).
fn decode_discrete(t: vec4<u32>, tau_in: f32) -> f32 {
    let n = f32(params.times);
    let tau = wrap(tau_in, n);
    var seg = 3u;
    for (var s = 0u; s < 4u; s++) {
        if (f32(texel_byte(t, 4u * s)) <= tau) {
            seg = s;
        }
    }
    let start = f32(texel_byte(t, 4u * seg));
    let x = wrap(tau - start, n) / n;
    let c0 = f32(texel_byte(t, 4u * seg + 1u)) * (8.0 / 255.0) - 4.0;
    let c1 = f32(texel_byte(t, 4u * seg + 2u)) * (8.0 / 255.0) - 4.0;
    let c2 = f32(texel_byte(t, 4u * seg + 3u)) * (8.0 / 255.0) - 4.0;
    return clamp(c0 + c1 * x + c2 * x * x, 0.0, 1.0);
}

// Word `w` (0..16) of a continuous texel's 64 bytes.
fn continuous_word(face: u32, i: u32, j: u32, w: u32) -> u32 {
    return texel_at((w / 4u) * 6u + face, i, j)[w % 4u];
}

// Byte `b` (0..64) of a continuous texel's 64 bytes.
fn continuous_byte(face: u32, i: u32, j: u32, b: u32) -> u32 {
    return (continuous_word(face, i, j, b / 4u) >> ((b % 4u) * 8u)) & 0xffu;
}

// Byte `b` (0..64) of a continuous texel's 64 bytes, as a residual node.
fn continuous_node(face: u32, i: u32, j: u32, b: u32) -> f32 {
    let byte = continuous_byte(face, i, j, b);
    return f32(bitcast<i32>(byte << 24u) >> 24u) * (0.5 / 127.0);
}

// The two residual cubics (bytes 50..58) at time tau and shell k.
fn residual_curves(face: u32, i: u32, j: u32, tau: f32, k: f32) -> f32 {
    let times = f32(params.times);
    let shells = f32(params.shells);
    var du = 0.0;
    if (params.shells > 1u) {
        du = clamp(k / (shells - 1.0), 0.0, 1.0);
    }
    let ld = lagrange(du);
    let lt = lagrange(wrap(tau / times, 1.0));
    var v = 0.0;
    for (var n = 0u; n < 4u; n++) {
        v += ld[n] * continuous_node(face, i, j, 50u + n);
        v += lt[n] * continuous_node(face, i, j, 54u + n);
    }
    return v;
}

// Kroon's layout: the third of the cycle tau falls in is a channel of a
// 5 × 5 Blurhash (DC bytes 0..3, the AC maximum at byte 3, 24 × 13 bits of
// three 19-level values from byte 4), plus the residual cubics.
fn decode_thirds(face: u32, i: u32, j: u32, tau_in: f32, k: f32) -> f32 {
    let times = f32(params.times);
    let shells = f32(params.shells);
    let tau = wrap(tau_in, times);
    let len = times / 3.0;
    let c = min(u32(floor(tau / len)), 2u);
    let x = (tau - f32(c) * len + 0.5) / len;
    let y = (k + 0.5) / shells;
    let actual_max = (f32(continuous_byte(face, i, j, 3u)) + 1.0) / 166.0;
    var divisor = 1u;
    if (c == 0u) {
        divisor = 361u;
    } else if (c == 1u) {
        divisor = 19u;
    }
    var v = f32(continuous_byte(face, i, j, c)) / 255.0;
    for (var n = 1u; n < 25u; n++) {
        let bit = 13u * (n - 1u);
        var packed = 0u;
        for (var b = 0u; b < 13u; b++) {
            let at = bit + b;
            packed |= ((continuous_byte(face, i, j, 4u + at / 8u) >> (at % 8u)) & 1u) << b;
        }
        let q = f32((packed / divisor) % 19u);
        let s = (q - 9.0) / 9.0;
        let value = sign(s) * s * s * actual_max;
        v += value * cos(PI * f32(n / 5u) * x) * cos(PI * f32(n % 5u) * y);
    }
    return clamp(v + residual_curves(face, i, j, tau, k), 0.0, 1.0);
}

fn lagrange(u: f32) -> vec4<f32> {
    let n = vec4<f32>(0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0);
    var w = vec4<f32>(1.0);
    for (var a = 0u; a < 4u; a++) {
        for (var b = 0u; b < 4u; b++) {
            if (b != a) {
                w[a] *= (u - n[b]) / (n[a] - n[b]);
            }
        }
    }
    return w;
}

// The texel's (time × distance) field at time tau and shell k.
fn decode_continuous(face: u32, i: u32, j: u32, tau_in: f32, k: f32) -> f32 {
    let times = f32(params.times);
    let shells = f32(params.shells);
    let tau = wrap(tau_in, times);
    let xt = (tau + 0.5) / times;
    let xd = (k + 0.5) / shells;
    var v = 0.0;
    for (var a = 0u; a < 5u; a++) {
        var row = 0.0;
        for (var b = 0u; b < 5u; b++) {
            let q = 5u * a + b;
            let bits = half_of(continuous_word(face, i, j, q / 2u), q);
            row += f16_bits_to_f32(bits) * cos(PI * f32(b) * xd);
        }
        v += row * cos(PI * f32(a) * xt);
    }
    return clamp(v + residual_curves(face, i, j, tau, k), 0.0, 1.0);
}

// The decoded value of texel (i, j) of `face` at time tau on shell k.
fn decode_texel(face: u32, i: u32, j: u32, tau: f32, k: f32) -> f32 {
    if (params.encoding == 1u) {
        return decode_continuous(face, i, j, tau, k);
    }
    if (params.encoding == 2u) {
        return decode_thirds(face, i, j, tau, k);
    }
    let last = params.shells - 1u;
    let k0 = min(u32(floor(k)), last);
    let k1 = min(k0 + 1u, last);
    let f = clamp(k - f32(k0), 0.0, 1.0);
    let a = decode_discrete(texel_at(k0 * 6u + face, i, j), tau);
    if (f == 0.0) {
        return a;
    }
    return a + f * (decode_discrete(texel_at(k1 * 6u + face, i, j), tau) - a);
}

// The face of a direction and its texel coordinates (s, t) in [0, 1]².
fn face_of(d: vec3<f32>) -> vec3<f32> {
    let a = abs(d);
    var face = 0.0;
    var sc = 0.0;
    var tc = 0.0;
    var ma = 0.0;
    if (a.x >= a.y && a.x >= a.z) {
        ma = a.x;
        if (d.x >= 0.0) {
            face = 0.0; sc = -d.z; tc = -d.y;
        } else {
            face = 1.0; sc = d.z; tc = -d.y;
        }
    } else if (a.y >= a.z) {
        ma = a.y;
        if (d.y >= 0.0) {
            face = 2.0; sc = d.x; tc = d.z;
        } else {
            face = 3.0; sc = d.x; tc = -d.z;
        }
    } else {
        ma = a.z;
        if (d.z >= 0.0) {
            face = 4.0; sc = d.x; tc = -d.y;
        } else {
            face = 5.0; sc = -d.x; tc = -d.y;
        }
    }
    ma = max(ma, 1.17549435e-38);
    return vec3<f32>(face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0));
}

// Occlusion cast by the character at world point p at `phase` in [0, 1).
fn cubemap_occlusion(p: vec3<f32>, phase: f32) -> f32 {
    let q = (p - params.centre.xyz) / params.radii.xyz;
    let len = length(q);
    var dir = vec3<f32>(0.0, 1.0, 0.0);
    if (len > 0.0) {
        dir = q / len;
    }
    let rho = len / params.centre.w;
    let inner = params.radii.w;
    let shells = f32(params.shells);
    var k = (rho - inner) * shells / (1.0 - inner) - 1.0;
    let fade = clamp(shells - k, 0.0, 1.0);
    if (!(fade > 0.0)) {
        return 0.0;
    }
    k = clamp(k, 0.0, shells - 1.0);
    let tau = wrap(phase, 1.0) * f32(params.times);
    let f = face_of(dir);
    let face = u32(f.x);
    let res = params.resolution;
    let last = f32(res - 1u);
    let x = clamp(f.y * f32(res) - 0.5, 0.0, last);
    let y = clamp(f.z * f32(res) - 0.5, 0.0, last);
    let i0 = u32(floor(x));
    let j0 = u32(floor(y));
    let i1 = min(i0 + 1u, res - 1u);
    let j1 = min(j0 + 1u, res - 1u);
    let fx = x - f32(i0);
    let fy = y - f32(j0);
    let a = decode_texel(face, i0, j0, tau, k);
    let top = a + fx * (decode_texel(face, i1, j0, tau, k) - a);
    let c = decode_texel(face, i0, j1, tau, k);
    let bottom = c + fx * (decode_texel(face, i1, j1, tau, k) - c);
    return fade * (top + fy * (bottom - top));
}


// The occlusion at a point p of the ground plane (CubemapModel::ground_ao):
// with a static ground (common/ground_texture.wgsl), the cubemap times the
// ground's gain plus the texture's offset at p, clamped to [0, 1]; without
// one, cubemap_occlusion.
fn cubemap_ground_ao(p: vec3<f32>, phase: f32) -> f32 {
    let c = cubemap_occlusion(p, phase);
    if (ground_word(0u) == 0u) {
        return c;
    }
    return clamp(ground_gain() * c + ground_offset(p), 0.0, 1.0);
}

// What a batch of points gets: cubemap_ground_ao on the ground,
// cubemap_occlusion elsewhere.
fn cubemap_point(p: vec3<f32>, phase: f32) -> f32 {
    if (params.on_ground == 1u) {
        return cubemap_ground_ao(p, phase);
    }
    return cubemap_occlusion(p, phase);
}
