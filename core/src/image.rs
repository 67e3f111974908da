//! Images as aobake writes them, for every floor that draws one (report
//! plots, cubemap charts, grid slices, previews): the bundled plot font,
//! linear-to-sRGB bytes, the error heat map, and the one PNG/APNG
//! encoder, with one error type.

use std::sync::OnceLock;

use plotters::style::{FontStyle, register_font};

/// Why an image could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImageError {
    /// The PNG encoder refused the image.
    #[error("cannot encode a PNG: {0}")]
    Png(String),
    /// The bundled font did not load.
    #[error("the bundled font is invalid")]
    Font,
    /// An animation without frames.
    #[error("an animation needs frames")]
    NoFrames,
}

impl From<ImageError> for String {
    fn from(e: ImageError) -> Self {
        e.to_string()
    }
}

/// The font of plots and previews' labels (DejaVu Sans, Bitstream Vera
/// licence: `assets/DejaVuSans-LICENSE.txt`), so that drawing needs no
/// system fonts.
pub(crate) static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Registers the bundled font as plotters' `sans-serif` (once).
pub(crate) fn register_plot_font() -> Result<(), ImageError> {
    static REGISTERED: OnceLock<Result<(), ImageError>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font("sans-serif", FontStyle::Normal, FONT).map_err(|_| ImageError::Font)
        })
        .clone()
}

fn png_error(e: png::EncodingError) -> ImageError {
    ImageError::Png(e.to_string())
}

/// What a PNG holds: plain RGB8 pixels (plots and charts), or sRGB-tagged
/// [`Image`]s: one, or an animation's frames with seconds per frame.
enum Pixels<'a> {
    Rgb(&'a [u8]),
    /// Grey samples: bytes at 8 bits, big-endian pairs at 16.
    Grey(&'a [u8], png::BitDepth),
    Rgba(&'a [Image], Option<f32>),
}

/// The one PNG encoder: one image, or an APNG that loops forever with
/// `delay` seconds per frame.
fn encode(pixels: Pixels<'_>, width: u32, height: u32) -> Result<Vec<u8>, ImageError> {
    let mut out = Vec::new();
    {
        let mut e = png::Encoder::new(&mut out, width, height);
        e.set_depth(png::BitDepth::Eight);
        match &pixels {
            Pixels::Rgb(_) => e.set_color(png::ColorType::Rgb),
            Pixels::Grey(_, depth) => {
                e.set_color(png::ColorType::Grayscale);
                e.set_depth(*depth);
            }
            Pixels::Rgba(frames, animation) => {
                e.set_color(png::ColorType::Rgba);
                e.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
                if let Some(delay) = animation {
                    e.set_animated(frames.len() as u32, 0).map_err(png_error)?;
                    let ms = (1000.0 * delay).round().clamp(1.0, 65_535.0) as u16;
                    e.set_frame_delay(ms, 1000).map_err(png_error)?;
                }
            }
        }
        let mut w = e.write_header().map_err(png_error)?;
        match pixels {
            Pixels::Rgb(rgb) | Pixels::Grey(rgb, _) => {
                w.write_image_data(rgb).map_err(png_error)?
            }
            Pixels::Rgba(frames, _) => {
                for f in frames {
                    w.write_image_data(&f.rgba).map_err(png_error)?;
                }
            }
        }
        w.finish().map_err(png_error)?;
    }
    Ok(out)
}

/// An RGB8 image as PNG bytes.
pub(crate) fn encode_rgb_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, ImageError> {
    encode(Pixels::Rgb(rgb), width, height)
}

/// A grey PNG of 8-bit samples, row-major.
pub(crate) fn encode_grey8_png(
    samples: &[u8],
    width: u32,
    height: u32,
) -> Result<Vec<u8>, ImageError> {
    encode(Pixels::Grey(samples, png::BitDepth::Eight), width, height)
}

/// A grey PNG of 16-bit samples, row-major.
pub(crate) fn encode_grey16_png(
    samples: &[u16],
    width: u32,
    height: u32,
) -> Result<Vec<u8>, ImageError> {
    let bytes: Vec<u8> = samples.iter().flat_map(|s| s.to_be_bytes()).collect();
    encode(Pixels::Grey(&bytes, png::BitDepth::Sixteen), width, height)
}

/// A PNG of one image.
pub fn encode_image(image: &Image) -> Result<Vec<u8>, ImageError> {
    encode(
        Pixels::Rgba(std::slice::from_ref(image), None),
        image.width,
        image.height,
    )
}

/// An APNG that loops forever, `delay` seconds per frame.
pub fn encode_apng(frames: &[Image], delay: f32) -> Result<Vec<u8>, ImageError> {
    let first = frames.first().ok_or(ImageError::NoFrames)?;
    if frames
        .iter()
        .any(|f| (f.width, f.height) != (first.width, first.height))
    {
        return Err(ImageError::Png(
            "an animation's frames differ in size".into(),
        ));
    }
    encode(Pixels::Rgba(frames, Some(delay)), first.width, first.height)
}

/// The sRGB byte of a linear value.
pub fn srgb_byte(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// The error colour ramp, written once here: the renderer gets these
/// numbers as uniforms and the legend is drawn from them. Colours are
/// linear RGB; an error `e = model − truth` (occlusion) maps to
/// `mix(neutral, too_dark, e / range)` above zero and
/// `mix(neutral, too_bright, −e / range)` below, clamped at `range`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatMap {
    /// Error magnitude that saturates the colour.
    pub range: f32,
    /// Colour of no error.
    pub neutral: [f32; 3],
    /// Colour of a model darker than the truth (more occlusion).
    pub too_dark: [f32; 3],
    /// Colour of a model brighter than the truth.
    pub too_bright: [f32; 3],
}

/// The ramp every preview uses: ±0.1 occlusion saturates (a good bake's
/// errors are a few hundredths; a tenth is plainly wrong).
pub const HEAT_MAP: HeatMap = HeatMap {
    range: 0.1,
    neutral: [0.9, 0.9, 0.9],
    too_dark: [0.8, 0.02, 0.01],
    too_bright: [0.01, 0.1, 0.8],
};

impl HeatMap {
    /// The linear colour of an error.
    pub fn color(&self, error: f32) -> [f32; 3] {
        let s = (error / self.range).clamp(-1.0, 1.0);
        let (to, f) = if s >= 0.0 {
            (self.too_dark, s)
        } else {
            (self.too_bright, -s)
        };
        std::array::from_fn(|i| self.neutral[i] + (to[i] - self.neutral[i]) * f)
    }
}

/// An sRGB-encoded RGBA8 image, rows top to bottom.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `4 × width × height` bytes.
    pub rgba: Vec<u8>,
}

/// Named float channels of one image (an asset's data, as `aobake
/// export` writes it to OpenEXR).
#[derive(Debug, Clone, PartialEq)]
pub struct FloatImage {
    /// The file name.
    pub file: String,
    /// The layer's name.
    pub layer: String,
    /// What the values are.
    pub comment: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Named channels, each `width × height` values, rows top to bottom.
    pub channels: Vec<(String, Vec<f32>)>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heat_map_is_neutral_at_zero_and_saturates_at_its_range() {
        let h = HEAT_MAP;
        let near = |a: [f32; 3], b: [f32; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert_eq!(h.color(0.0), h.neutral);
        assert!(near(h.color(h.range), h.too_dark));
        assert!(near(h.color(10.0), h.too_dark));
        assert!(near(h.color(-h.range), h.too_bright));
        let half = h.color(0.5 * h.range);
        assert!(half[0] > half[2], "too dark leans red: {half:?}");
        let half = h.color(-0.5 * h.range);
        assert!(half[2] > half[0], "too bright leans blue: {half:?}");
    }

    #[test]
    fn an_apng_holds_every_frame_and_loops() {
        let frame = |v: u8| Image {
            width: 4,
            height: 3,
            rgba: vec![v; 48],
        };
        let frames = [frame(0), frame(100), frame(200)];
        let bytes = encode_apng(&frames, 0.04).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let control = reader.info().animation_control.unwrap();
        assert_eq!((control.num_frames, control.num_plays), (3, 0));
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        for want in [0u8, 100, 200] {
            reader.next_frame(&mut buf).unwrap();
            assert!(buf[..48].iter().all(|&b| b == want));
            let fc = reader.info().frame_control.unwrap();
            assert_eq!((fc.delay_num, fc.delay_den), (40, 1000));
        }
    }
}
