//! A baked cubemap in the asset container (DESIGN §7): the JSON header
//! carries the [`CubemapLayout`] (spheroid, resolution, time samples,
//! encoding, the clip's duration) and one section, `TEXL`, holds the
//! texels exactly as an engine uploads them (layer-major, 16 bytes a
//! texel; `model` describes the layout); with a static ground (format
//! 1.5), the header's `ground` (gain and square) and `GOFS`, its offsets
//! (f16, x fastest). Reading checks every number of
//! the layout and the section's length, so a hostile file with valid
//! checksums is refused with a message.

use half::f16;
use serde::{Deserialize, Serialize};

use super::{
    ALGORITHM_VERSION, continuous,
    geometry::FACES,
    model::{CubemapLayout, CubemapModel, Encoding},
};
use crate::{
    Method,
    container::{AssetError, AssetHeaderFields, Container, Data, Section},
    method::ground::{GroundBase, GroundSquare},
};

/// What the stored values mean, written into every header.
pub const UNITS: &str = "occlusion cast into space by the character: 0 = open, 1 = blocked";

/// A cubemap asset's JSON header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CubemapHeader {
    /// The program that wrote it.
    pub generator: String,
    /// The method.
    pub method: Method,
    /// [`ALGORITHM_VERSION`] of the writer.
    pub algorithm_version: u32,
    /// The bake key.
    pub bake_key: String,
    /// sha256 of the character upload.
    pub character: String,
    /// sha256 of each clip upload.
    pub clips: Vec<String>,
    /// The baked clip's name.
    pub clip: String,
    /// What the values mean.
    pub units: String,
    /// The bake's fully defaulted parameters.
    pub params: serde_json::Value,
    /// Where the cubemaps sit and how the texels are laid out.
    pub layout: CubemapLayout,
    /// The static ground (format 1.5): its square and gain; `GOFS` holds
    /// its texels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground: Option<GroundLayout>,
}

/// A static ground as the header describes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GroundLayout {
    /// The gain of the cubemap's change on the ground.
    pub gain: f32,
    /// Where the texture lies.
    pub square: GroundSquare,
}

impl CubemapModel {
    /// The method this model's encoding is.
    pub fn method(&self) -> Method {
        match self.layout.encoding {
            Encoding::Discrete => Method::CubemapDiscrete,
            Encoding::Continuous | Encoding::Thirds => Method::CubemapContinuous,
        }
    }

    /// The asset: header and the texel section.
    pub fn to_container(&self, fields: AssetHeaderFields, clip: &str) -> Container {
        let header = CubemapHeader {
            generator: fields.generator,
            method: self.method(),
            algorithm_version: ALGORITHM_VERSION,
            bake_key: fields.bake_key,
            character: fields.character,
            clips: fields.clips,
            clip: clip.to_owned(),
            units: UNITS.to_owned(),
            params: fields.params,
            layout: self.layout,
            ground: self.ground.as_ref().map(|g| GroundLayout {
                gain: g.gain,
                square: g.square,
            }),
        };
        let mut sections = vec![Section {
            tag: *b"TEXL",
            data: Data::U8(self.texels.clone()),
        }];
        if let Some(g) = &self.ground {
            sections.push(Section {
                tag: *b"GOFS",
                data: g.section_data(),
            });
        }
        Container::new(self.method(), &header, sections)
    }

    /// Reads a model back, checking the layout and the section's length.
    pub fn from_container(container: &Container) -> Result<(Self, CubemapHeader), AssetError> {
        if container.method.family() != crate::Family::Cubemap {
            return Err(AssetError::Unsupported(format!(
                "a {} asset is not a cubemap",
                container.method.name()
            )));
        }
        let header: CubemapHeader = container.header()?;
        if header.method != container.method {
            return Err(bad("the header's method differs from the preamble's"));
        }
        let layout = header.layout;
        validate(&layout)?;
        let method_of = Self {
            layout,
            texels: Vec::new(),
            ground: None,
        }
        .method();
        if method_of != header.method {
            return Err(bad("the layout's encoding is not the method's"));
        }
        let Data::U8(texels) = container.section(b"TEXL")? else {
            return Err(bad("TEXL must be bytes"));
        };
        if texels.len() != layout.texel_bytes() {
            return Err(bad(&format!(
                "TEXL holds {} bytes where the layout needs {}",
                texels.len(),
                layout.texel_bytes()
            )));
        }
        check_coefficients(&layout, texels)?;
        let ground = match header.ground {
            Some(g) => Some(GroundBase::read(container, g.square, g.gain, b"GOFS")?),
            None => None,
        };
        Ok((
            Self {
                layout,
                texels: texels.clone(),
                ground,
            },
            header,
        ))
    }
}

/// Checks that every half-float coefficient of the continuous (cosine)
/// encoding is a finite number: an infinite one times a basis value of 0
/// would decode as NaN. (A texel's 64 bytes are 16 in each of four
/// cubemaps; its first 50 hold the 25 coefficients, so cubemaps 0 to 2
/// hold eight each and cubemap 3 one.) The discrete and the thirds
/// encodings store quantised integers: any bytes are numbers.
fn check_coefficients(l: &CubemapLayout, texels: &[u8]) -> Result<(), AssetError> {
    if l.encoding != Encoding::Continuous {
        return Ok(());
    }
    let per_cubemap = FACES * l.resolution * l.resolution * 16;
    let halves = continuous::BASIS * continuous::BASIS;
    for (c, cubemap) in texels.chunks(per_cubemap).enumerate() {
        let in_this = halves.saturating_sub(8 * c).min(8);
        for texel in cubemap.chunks_exact(16) {
            if texel[..2 * in_this]
                .chunks_exact(2)
                .any(|h| !f16::from_le_bytes([h[0], h[1]]).is_finite())
            {
                return Err(bad("TEXL holds a coefficient that is not a finite number"));
            }
        }
    }
    Ok(())
}

/// Checks a layout's numbers before anything is computed from them.
fn validate(l: &CubemapLayout) -> Result<(), AssetError> {
    let s = &l.spheroid;
    if !(1..=1024).contains(&l.resolution) {
        return Err(bad("the resolution must be between 1 and 1024"));
    }
    if !(1..=64).contains(&s.shells) {
        return Err(bad("the shell count must be between 1 and 64"));
    }
    if !(2..=256).contains(&l.times) {
        return Err(bad("the time sample count must be between 2 and 256"));
    }
    let finite = s.centre.is_finite() && s.radii.is_finite();
    if !finite || s.radii.min_element() <= 0.0 {
        return Err(bad(
            "the spheroid's centre or radii are not finite and positive",
        ));
    }
    if !(s.outer.is_finite() && s.outer > 0.0 && s.inner >= 0.0 && s.inner < 1.0) {
        return Err(bad("the spheroid's scaling is out of range"));
    }
    if !(l.duration.is_finite() && l.duration >= 0.0) {
        return Err(bad("the clip's duration is not a finite number ≥ 0"));
    }
    debug_assert!(l.cubemaps() * FACES * l.resolution * l.resolution <= 64 * 6 * 1024 * 1024);
    Ok(())
}

fn bad(what: &str) -> AssetError {
    AssetError::Malformed(what.to_owned())
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::method::cubemap::geometry::Spheroid;

    fn model(encoding: Encoding) -> CubemapModel {
        let layout = CubemapLayout {
            spheroid: Spheroid {
                centre: Vec3::new(0.0, 1.0, 0.0),
                radii: Vec3::new(0.4, 1.0, 0.3),
                outer: 1.1,
                inner: 0.25,
                shells: 3,
            },
            resolution: 2,
            times: 16,
            encoding,
            duration: 1.5,
        };
        // Any bytes, but each odd one (a half float's high byte, for the
        // continuous encodings) below 0x40: finite coefficients.
        let texels = (0..layout.texel_bytes())
            .map(|i| (i * 37) as u8 & if i % 2 == 1 { 0x3f } else { 0xff })
            .collect();
        CubemapModel {
            layout,
            texels,
            ground: None,
        }
    }

    #[test]
    fn a_model_round_trips_through_its_container_bit_for_bit() {
        for encoding in [Encoding::Discrete, Encoding::Continuous, Encoding::Thirds] {
            let m = model(encoding);
            let bytes = m
                .to_container(AssetHeaderFields::for_tests(), "walk")
                .to_bytes();
            let (back, header) =
                CubemapModel::from_container(&Container::from_bytes(&bytes).unwrap()).unwrap();
            assert_eq!(back, m);
            assert_eq!(header.clip, "walk");
            assert_eq!(header.method, m.method());
        }
    }

    #[test]
    fn the_phase_is_a_number_for_any_time_and_duration() {
        let mut l = model(Encoding::Discrete).layout;
        assert_eq!(l.phase(2.25), 0.5);
        assert_eq!(l.phase(-0.375), 0.75);
        assert_eq!(l.phase(f32::NAN), 0.0);
        // A clip of a subnormal duration, late: the ratio overflows.
        l.duration = 1e-40;
        assert_eq!(l.phase(1e9), 0.0);
        l.duration = 0.0;
        assert_eq!(l.phase(1.0), 0.0);
    }

    #[test]
    fn a_hostile_layout_is_refused_by_name() {
        type Break = fn(&mut CubemapModel);
        let cases: [(&str, Break); 5] = [
            ("resolution", |m| m.layout.resolution = 0),
            ("shell count", |m| m.layout.spheroid.shells = 1000),
            ("radii", |m| m.layout.spheroid.radii.x = -1.0),
            ("duration", |m| m.layout.duration = -1.0),
            ("TEXL holds", |m| {
                m.texels.pop();
            }),
        ];
        let refusal = |m: &CubemapModel| {
            let c = Container::from_bytes(
                &m.to_container(AssetHeaderFields::for_tests(), "walk")
                    .to_bytes(),
            )
            .unwrap();
            CubemapModel::from_container(&c).unwrap_err().to_string()
        };
        for (what, break_it) in cases {
            let mut m = model(Encoding::Discrete);
            break_it(&mut m);
            let e = refusal(&m);
            assert!(e.contains(what), "{what}: {e}");
        }
        // An infinite coefficient of the cosine layout would decode as
        // NaN where its basis value is 0: in cubemap 0 (texel 5's
        // fourth), and in cubemap 3's one coefficient; bytes after a
        // texel's 50th are not coefficients.
        let res = model(Encoding::Continuous).layout.resolution;
        let per_cubemap = FACES * res * res * 16;
        for (at, encoding, refused) in [
            (5 * 16 + 6, Encoding::Continuous, true),
            (3 * per_cubemap + 7 * 16, Encoding::Continuous, true),
            (3 * per_cubemap + 7 * 16 + 2, Encoding::Continuous, false),
            // Thirds' bytes are quantised integers, not half floats.
            (5 * 16 + 6, Encoding::Thirds, false),
        ] {
            let mut m = model(encoding);
            m.texels[at..at + 2].copy_from_slice(&f16::INFINITY.to_le_bytes());
            if refused {
                let e = refusal(&m);
                assert!(e.contains("not a finite number"), "{at}: {e}");
            } else {
                let c = m.to_container(AssetHeaderFields::for_tests(), "walk");
                assert!(CubemapModel::from_container(&c).is_ok(), "{at}");
            }
        }
    }
}
