//! OpenEXR through the `exr` crate, guarded.
//!
//! `exr` 1.74 aborts the process with a 1 TiB allocation on a 1.9 KB DWAA-compressed file, and an
//! abort cannot be caught. So every read first parses only the header and refuses what is not
//! safe to decode (compression it does not implement, deep data, absurd sizes) before any pixel
//! is touched; the decode itself runs under catch_unwind as a second line of defence.

use exr::prelude::*;
use glam::{Vec3, Vec4};
use std::path::Path;

use crate::error::{Error, Result};
use crate::image::Image;
use crate::scene::LatLongMap;

/// Largest environment map accepted: 16384 x 8192 RGBA f32 is 2 GiB.
pub const MAX_EXR_PIXELS: u64 = 16384 * 8192;

/// Checks the header of an EXR file; returns its data-window size.
pub fn check_header(path: &Path) -> Result<(usize, usize)> {
    let meta = std::panic::catch_unwind(|| exr::meta::MetaData::read_from_file(path, false))
        .map_err(|_| Error::format(path, "EXR header could not be parsed"))?
        .map_err(|e| Error::format(path, format!("not a readable EXR file: {e}")))?;
    let header = meta.headers.first().ok_or_else(|| Error::format(path, "EXR file has no image part"))?;
    for h in meta.headers.iter() {
        match h.compression {
            Compression::Uncompressed
            | Compression::RLE
            | Compression::ZIP1
            | Compression::ZIP16
            | Compression::PIZ
            | Compression::PXR24
            | Compression::B44
            | Compression::B44A => {}
            other => {
                return Err(Error::format(path, format!("EXR compression {other:?} is not supported; re-save with ZIP or PIZ")))
            }
        }
        if h.deep {
            return Err(Error::format(path, "deep EXR images are not supported"));
        }
        let area = h.layer_size.0 as u64 * h.layer_size.1 as u64;
        if h.layer_size.0 == 0 || h.layer_size.1 == 0 || area > MAX_EXR_PIXELS {
            return Err(Error::format(
                path,
                format!("EXR data window {}x{} is empty or over the limit of {MAX_EXR_PIXELS} pixels", h.layer_size.0, h.layer_size.1),
            ));
        }
        if h.channels.list.len() > 64 {
            return Err(Error::format(path, format!("EXR part has {} channels (limit 64)", h.channels.list.len())));
        }
    }
    Ok((header.layer_size.0, header.layer_size.1))
}

/// Reads a lat-long environment map (first RGB(A) layer).
pub fn read_latlong(path: &Path) -> Result<LatLongMap> {
    if !path.exists() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "file not found")));
    }
    let (w, h) = check_header(path)?;
    let decoded = std::panic::catch_unwind(|| {
        read_first_rgba_layer_from_file(
            path,
            |res, _| vec![Vec3::ZERO; res.width() * res.height()],
            move |pixels: &mut Vec<Vec3>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                pixels[pos.y() * w + pos.x()] = Vec3::new(r, g, b);
            },
        )
    })
    .map_err(|_| Error::format(path, "EXR decoding failed"))?
    .map_err(|e| Error::format(path, format!("EXR decoding failed: {e}")))?;
    let size = decoded.layer_data.size;
    if (size.0, size.1) != (w, h) {
        return Err(Error::format(path, "EXR size changed between header and data"));
    }
    let mut pixels = decoded.layer_data.channel_data.pixels;
    let mut bad = 0usize;
    for p in pixels.iter_mut() {
        if !p.is_finite() || p.min_element() < 0.0 {
            *p = p.max(Vec3::ZERO);
            if !p.is_finite() {
                *p = Vec3::ZERO;
            }
            bad += 1;
        }
    }
    if bad > 0 {
        eprintln!("warning: {}: {bad} pixels were NaN, infinite or negative and were set to zero", path.display());
    }
    Ok(LatLongMap::new(w, h, pixels))
}

/// Writes float RGBA plus every AOV as `name.R/G/B` channels of the same part (the layout
/// Blender's and Nuke's multilayer readers expect), ZIP-compressed.
pub fn write_image(path: &Path, image: &Image) -> Result<()> {
    let (w, h) = (image.width as usize, image.height as usize);
    let chan = |name: &str, f: &dyn Fn(usize) -> f32| AnyChannel::new(name, FlatSamples::F32((0..w * h).map(f).collect()));
    let rgba = &image.rgba;
    let mut channels: Vec<AnyChannel<FlatSamples>> = vec![
        chan("R", &|i| rgba[i].x),
        chan("G", &|i| rgba[i].y),
        chan("B", &|i| rgba[i].z),
        chan("A", &|i| rgba[i].w),
    ];
    for (name, data) in &image.aovs {
        channels.push(chan(&format!("{name}.R"), &|i| data[i].x));
        channels.push(chan(&format!("{name}.G"), &|i| data[i].y));
        channels.push(chan(&format!("{name}.B"), &|i| data[i].z));
    }
    let layer = Layer::new(
        (w, h),
        LayerAttributes::named("volscatter"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    exr::image::Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| Error::format(path, format!("writing EXR failed: {e}")))
}

/// Reads back the RGBA of an EXR written by `write_image` (tests, `compare`).
pub fn read_rgba(path: &Path) -> Result<Image> {
    let (w, h) = check_header(path)?;
    let decoded = std::panic::catch_unwind(|| {
        read_first_rgba_layer_from_file(
            path,
            |res, _| vec![Vec4::ZERO; res.width() * res.height()],
            move |pixels: &mut Vec<Vec4>, pos, (r, g, b, a): (f32, f32, f32, f32)| {
                pixels[pos.y() * w + pos.x()] = Vec4::new(r, g, b, a);
            },
        )
    })
    .map_err(|_| Error::format(path, "EXR decoding failed"))?
    .map_err(|e| Error::format(path, format!("EXR decoding failed: {e}")))?;
    let mut img = Image::new(w as u32, h as u32);
    img.rgba = decoded.layer_data.channel_data.pixels;
    Ok(img)
}

/// Writes a lat-long environment map (tests and scripts make their skies with it).
pub fn write_latlong(path: &Path, width: usize, height: usize, pixels: &[Vec3]) -> Result<()> {
    let mut img = Image::new(width as u32, height as u32);
    img.rgba = pixels.iter().map(|p| p.extend(1.0)).collect();
    write_image(path, &img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_roundtrip_and_latlong_read() {
        let dir = std::env::temp_dir().join(format!("vs-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(5, 3);
        for (i, p) in img.rgba.iter_mut().enumerate() {
            *p = Vec4::new(i as f32, 0.5, 2.0, 0.25);
        }
        img.aovs.push(("single".into(), vec![Vec3::new(1.0, 2.0, 3.0); 15]));
        let path = dir.join("img.exr");
        write_image(&path, &img).unwrap();
        let back = read_rgba(&path).unwrap();
        assert_eq!(back.rgba, img.rgba);
        let env = read_latlong(&path).unwrap();
        assert_eq!((env.width, env.height), (5, 3));
        assert_eq!(env.pixels[7], Vec3::new(7.0, 0.5, 2.0));
    }

    /// exr 1.74 aborts the process (1 TiB allocation) decoding some DWAA files, so DWAA/DWAB
    /// must be refused from the header alone. A valid file whose compression attribute is
    /// patched to DWAA (8) must come back as a clear error before any decoding.
    #[test]
    fn dwaa_is_refused_from_the_header() {
        let dir = std::env::temp_dir().join(format!("vs-exr-dwaa-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("dwaa.exr");
        let mut img = Image::new(4, 4);
        img.rgba.fill(Vec4::ONE);
        write_image(&path, &img).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let key = b"compression\0compression\0\x01\0\0\0";
        let at = bytes.windows(key.len()).position(|w| w == key).expect("compression attribute") + key.len();
        bytes[at] = 8; // DWAA_COMPRESSION
        std::fs::write(&path, &bytes).unwrap();
        let e = read_latlong(&path).unwrap_err().to_string();
        assert!(e.contains("not supported") && e.contains("DWAA"), "{e}");
    }

    #[test]
    fn garbage_is_refused_with_a_message() {
        let dir = std::env::temp_dir().join(format!("vs-exr-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.exr");
        std::fs::write(&path, b"\x76\x2f\x31\x01garbage garbage").unwrap();
        let e = read_latlong(&path).unwrap_err().to_string();
        assert!(e.contains("bad.exr"), "{e}");
        assert!(read_latlong(&dir.join("missing.exr")).is_err());
    }
}
