//! Images as aobake writes them, for every floor that draws one (report
//! plots, cubemap charts, grid slices, previews): the bundled plot font,
//! linear-to-sRGB bytes and RGB PNG encoding, with one error type.

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

/// An RGB8 image as PNG bytes.
pub(crate) fn encode_rgb_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, ImageError> {
    let png_error = |e: png::EncodingError| ImageError::Png(e.to_string());
    let mut png = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(png_error)?;
        writer.write_image_data(rgb).map_err(png_error)?;
    }
    Ok(png)
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
