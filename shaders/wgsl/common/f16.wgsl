// Half floats stored two per u32 (little-endian: element 2i in the low 16
// bits). Decoded by hand rather than with unpack2x16float, which WGSL only
// guarantees where the adapter has f16-in-f32 support (lavapipe may not).

// IEEE 754 binary16 bits (in the low 16 bits of `h`) to f32, exactly:
// normals, subnormals, zeros, infinities and NaNs.
fn f16_bits_to_f32(h: u32) -> f32 {
    let sign = (h & 0x8000u) << 16u;
    let exponent = (h >> 10u) & 0x1fu;
    let mantissa = h & 0x3ffu;
    if (exponent == 0u) {
        // Zero or subnormal: mantissa × 2^-24.
        let magnitude = f32(mantissa) * 5.9604644775390625e-8;
        return select(magnitude, -magnitude, sign != 0u);
    }
    if (exponent == 31u) {
        return bitcast<f32>(sign | 0x7f800000u | (mantissa << 13u));
    }
    return bitcast<f32>(sign | ((exponent + 112u) << 23u) | (mantissa << 13u));
}

// Element `i` of an array of 16-bit values packed two per u32 word `word`.
fn half_of(word: u32, i: u32) -> u32 {
    return (word >> ((i & 1u) * 16u)) & 0xffffu;
}
