//! Encoding a baked cubemap: the six faces' traced fields into the texels
//! of a [`CubemapModel`] (the `assemble` job). The model, its layout and
//! its lookup are the runtime's (`aobake_runtime::method::cubemap::model`),
//! which engines use too.

pub use aobake_runtime::method::cubemap::model::{CubemapLayout, CubemapModel, Encoding};
use rayon::prelude::*;

use super::{
    continuous, discrete,
    face::{FaceField, dequantise},
    geometry::FACES,
};

/// Encodes the six faces' fields (in face order) into a model: the
/// `assemble` job's work. `continuous` says how the continuous
/// encoding weighs its residuals (unused by the discrete one).
pub fn encode(
    layout: CubemapLayout,
    faces: &[FaceField],
    continuous: continuous::Encoding,
) -> Result<CubemapModel, String> {
    let (res, shells, times) = (layout.resolution, layout.spheroid.shells, layout.times);
    if faces.len() != FACES
        || faces
            .iter()
            .any(|f| (f.resolution, f.shells, f.times) != (res, shells, times))
    {
        return Err("the face fields do not match the cubemap's layout".into());
    }
    let tables = continuous::Tables::new(times, shells);
    let texels = res * res;
    // Every texel's bytes for every cubemap, texel-major, in parallel.
    let cubemaps = layout.cubemaps();
    let per_texel: Vec<Vec<u8>> = (0..FACES * texels)
        .into_par_iter()
        .map(|n| {
            let block: Vec<f32> = faces[n / texels]
                .texel(n % texels)
                .iter()
                .map(|&b| dequantise(b))
                .collect();
            match layout.encoding {
                Encoding::Discrete => block
                    .chunks_exact(times)
                    .flat_map(discrete::encode)
                    .collect(),
                Encoding::Continuous => continuous::encode(&block, &tables, continuous).to_vec(),
                Encoding::Thirds => {
                    super::blurhash::encode(&block, times, shells, continuous).to_vec()
                }
            }
        })
        .collect();
    let mut bytes = vec![0u8; layout.texel_bytes()];
    for (n, texel) in per_texel.iter().enumerate() {
        let (face, t) = (n / texels, n % texels);
        for c in 0..cubemaps {
            let o = layout.offset(c, face, t % res, t / res);
            bytes[o..o + 16].copy_from_slice(&texel[16 * c..16 * c + 16]);
        }
    }
    Ok(CubemapModel {
        layout,
        texels: bytes,
        ground: None,
    })
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::method::cubemap::geometry::Spheroid;

    fn layout(encoding: Encoding) -> CubemapLayout {
        CubemapLayout {
            spheroid: Spheroid {
                centre: Vec3::ZERO,
                radii: Vec3::ONE,
                outer: 1.0,
                inner: 0.0,
                shells: 4,
            },
            resolution: 4,
            times: 64,
            encoding,
            duration: 2.0,
        }
    }

    /// A discrete model whose every texel on shell `k` holds the constant
    /// `values[k]`.
    fn constant_shells(values: [f32; 4]) -> CubemapModel {
        let l = layout(Encoding::Discrete);
        let mut texels = vec![0u8; l.texel_bytes()];
        for (k, v) in values.iter().enumerate() {
            let bytes = discrete::encode(&[*v; 64]);
            for face in 0..FACES {
                for j in 0..4 {
                    for i in 0..4 {
                        let o = l.offset(k, face, i, j);
                        texels[o..o + 16].copy_from_slice(&bytes);
                    }
                }
            }
        }
        CubemapModel {
            layout: l,
            texels,
            ground: None,
        }
    }

    #[test]
    fn shells_blend_by_radius_and_fade_out_beyond_the_last() {
        let m = constant_shells([0.8, 0.6, 0.4, 0.2]);
        let q = |x: f32| m.occlusion(Vec3::new(x, 0.0, 0.0), 0.3);
        // Shells at ρ = 0.25, 0.5, 0.75, 1; values within a byte step.
        let step = 8.0 / 255.0;
        assert!((q(0.1) - 0.8).abs() < step, "inside the first shell");
        assert!((q(0.5) - 0.6).abs() < step);
        assert!((q(0.625) - 0.5).abs() < step, "halfway between shells");
        assert!((q(1.125) - 0.1).abs() < step, "half faded");
        assert_eq!(q(1.3), 0.0);
        assert_eq!(m.occlusion(Vec3::NAN, 0.0), 0.0);
    }

    /// A smooth field on every face: darker towards the inner shells and
    /// towards +y, varying over the cycle.
    fn smooth_faces(l: &CubemapLayout) -> Vec<FaceField> {
        use super::super::geometry::texel_direction;
        let (res, shells, times) = (l.resolution, l.spheroid.shells, l.times);
        (0..FACES)
            .map(|face| {
                let mut f = FaceField::new(res, shells, times);
                for t in 0..times {
                    let phase = t as f32 / times as f32;
                    let slice: Vec<u8> = (0..shells * res * res)
                        .map(|p| {
                            let (k, texel) = (p / (res * res), p % (res * res));
                            let d = texel_direction(face, texel % res, texel / res, res);
                            let v = (0.5 - 0.1 * k as f32)
                                * (0.6 + 0.3 * d.y)
                                * (0.8 + 0.2 * (std::f32::consts::TAU * phase).cos());
                            super::super::face::quantise(v)
                        })
                        .collect();
                    f.insert(t, &slice);
                }
                f
            })
            .collect()
    }

    #[test]
    fn both_encodings_give_back_a_smooth_field_at_its_sample_points() {
        use super::super::geometry::texel_direction;
        for (encoding, tolerance) in [
            (Encoding::Discrete, 0.025),
            (Encoding::Continuous, 0.01),
            // Blurhash quantises AC terms to 19 levels: coarser.
            (Encoding::Thirds, 0.045),
        ] {
            let l = layout(encoding);
            let faces = smooth_faces(&l);
            let m = encode(
                l,
                &faces,
                continuous::Encoding {
                    bright_weight: 0.6,
                    residuals: true,
                },
            )
            .unwrap();
            assert_eq!(m.bytes(), l.texel_bytes());
            let mut worst = 0.0f32;
            for (face, field) in faces.iter().enumerate() {
                for texel in [0, 5, 10, 15] {
                    let (i, j) = (texel % 4, texel / 4);
                    let d = texel_direction(face, i, j, 4);
                    for k in 0..4 {
                        for t in [0, 17, 40, 63] {
                            let p = l.spheroid.point(d, k);
                            let got = m.occlusion(p, t as f32 / 64.0);
                            let want = dequantise(field.texel(texel)[k * 64 + t]);
                            worst = worst.max((got - want).abs());
                        }
                    }
                }
            }
            assert!(worst < tolerance, "{encoding:?}: worst {worst}");
        }
        assert!(
            encode(
                layout(Encoding::Discrete),
                &[],
                continuous::Encoding {
                    bright_weight: 0.6,
                    residuals: true,
                }
            )
            .is_err()
        );
    }

    #[test]
    fn the_phase_is_cyclic() {
        let l = layout(Encoding::Continuous);
        assert_eq!(l.phase(0.5), 0.25);
        assert_eq!(l.phase(2.5), 0.25);
        assert_eq!(l.phase(-0.5), 0.75);
        assert_eq!(l.cubemaps(), 4);
        assert_eq!(l.texel_bytes(), 4 * 6 * 16 * 16);
    }
}
