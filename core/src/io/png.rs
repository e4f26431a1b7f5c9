//! 8-bit sRGB PNG previews of linear renders (clamped, no tone mapping beyond exposure).

use std::path::Path;

use crate::error::{Error, Result};
use crate::image::Image;

fn srgb_encode(x: f32) -> u8 {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    let s = if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// `exposure` multiplies radiance before encoding. With `transparent`, writes straight alpha.
pub fn write_png(path: &Path, image: &Image, exposure: f32, transparent: bool) -> Result<()> {
    // Encoded in memory, written by `write_file`: the encoder's own writes to a BufWriter would
    // lose an error raised when it is dropped.
    let mut bytes = Vec::new();
    let mut enc = png::Encoder::new(&mut bytes, image.width, image.height);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut data = Vec::with_capacity(image.rgba.len() * 4);
    for p in &image.rgba {
        let (rgb, a) = if transparent && p.w > 1e-4 {
            (p.truncate() * exposure / p.w, p.w)
        } else if transparent {
            (glam::Vec3::ZERO, 0.0)
        } else {
            (p.truncate() * exposure, 1.0)
        };
        data.extend_from_slice(&[srgb_encode(rgb.x), srgb_encode(rgb.y), srgb_encode(rgb.z), (a.clamp(0.0, 1.0) * 255.0 + 0.5) as u8]);
    }
    let mut w = enc.write_header().map_err(|e| Error::format(path, e.to_string()))?;
    w.write_image_data(&data).map_err(|e| Error::format(path, e.to_string()))?;
    w.finish().map_err(|e| Error::format(path, e.to_string()))?;
    super::files::write_file_atomic(path, &bytes)
}
