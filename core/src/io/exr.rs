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

/// Largest environment map accepted: 16384 x 8192 RGBA f32 is 2 GiB.
pub const MAX_EXR_PIXELS: u64 = 16384 * 8192;

/// Checks the header of an EXR file; returns its data-window size.
pub fn check_header(path: &Path) -> Result<(usize, usize)> {
    super::files::regular_file(path, "EXR file")?;
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

/// Largest dome map kept in memory: 4096 x 2048 (0.09 degrees a pixel). No solver resolves
/// lighting finer than that: pop decomposes the sky into at most a few hundred ordinates, the
/// reference tracer importance-samples the map (a sun 0.53 degrees wide still covers ~35 pixels),
/// and the map, its sampling tables and pop's importance map at this size take ~250 MB, where a
/// 16384 x 8192 map took 3-4.7 GB. Larger maps are box-filtered down while they are read.
pub const MAX_DOME_PIXELS: u64 = 4096 * 2048;

/// Bytes per kept dome pixel for the budget: the RGB sum while reading (12), then the map's
/// pixels (12) and its sampling tables (`LatLongMap::new`: function + two CDF levels, ~12).
const DOME_BYTES_PER_PIXEL: u64 = 36;

/// A decoded block is held whole, and the decompressor holds the compressed and one or two
/// working copies of it: three times its decoded size is what one block costs.
const BLOCK_COPIES: u64 = 3;

/// An RGB image as read, rows top to bottom, with what the reading changed.
#[derive(Debug)]
pub struct RgbPixels {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Vec3>,
    /// What the host should tell the user (the map was reduced, bad pixels were zeroed).
    pub notes: Vec<String>,
}

/// Reads a lat-long environment map (the first part with R, G and B channels), box-filtered
/// down to at most [`MAX_DOME_PIXELS`].
pub fn read_latlong(path: &Path) -> Result<RgbPixels> {
    read_latlong_at_most(path, MAX_DOME_PIXELS)
}

/// The integer box-filter factor that brings `w` x `h` to at most `max_pixels`.
fn reduction_factor(w: usize, h: usize, max_pixels: u64) -> usize {
    let mut f = 1usize;
    while (w.div_ceil(f) as u64) * (h.div_ceil(f) as u64) > max_pixels.max(1) {
        f += 1;
    }
    f
}

/// [`read_latlong`] with an explicit pixel limit. The file is decoded block by block (one tile or
/// scanline group at a time), each block added into the reduced map, so memory is the reduced
/// map plus one block, both checked against the memory budget before they are allocated.
pub fn read_latlong_at_most(path: &Path, max_pixels: u64) -> Result<RgbPixels> {
    if !path.exists() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "file not found")));
    }
    let (w, h) = check_header(path)?;
    let factor = reduction_factor(w, h, max_pixels);
    let (ow, oh) = (w.div_ceil(factor), h.div_ceil(factor));
    let sums = std::panic::catch_unwind(|| decode_reduced(path, (w, h), factor))
        .map_err(|_| Error::format(path, "EXR decoding failed"))??;
    let mut notes = Vec::new();
    if factor > 1 {
        notes.push(format!("{}: dome map {w}x{h} read at {ow}x{oh} (box filter {factor}x{factor}); no solver uses finer lighting", path.display()));
    }
    let mut pixels = sums;
    let mut bad = 0usize;
    for (i, p) in pixels.iter_mut().enumerate() {
        // Edge boxes are partial when the size is not a multiple of the factor.
        let (ox, oy) = (i % ow, i / ow);
        let area = (factor.min(w - ox * factor) * factor.min(h - oy * factor)) as f32;
        *p /= area;
        if !p.is_finite() || p.min_element() < 0.0 {
            *p = p.max(Vec3::ZERO);
            if !p.is_finite() {
                *p = Vec3::ZERO;
            }
            bad += 1;
        }
    }
    if bad > 0 {
        notes.push(format!("{}: {bad} pixels were NaN, infinite or negative and were set to zero", path.display()));
    }
    Ok(RgbPixels { width: ow, height: oh, pixels, notes })
}

/// Which of R, G, B a channel name is: `R` or `<layer>.R`, any case.
fn rgb_index(name: &str) -> Option<(&str, usize)> {
    let (prefix, last) = name.rsplit_once('.').unwrap_or(("", name));
    let c = ["R", "G", "B"].iter().position(|c| c.eq_ignore_ascii_case(last))?;
    Some((prefix, c))
}

/// The part and its R, G, B channel indices: the first part, and in it the first layer prefix
/// (`""` before named layers), with all three at full resolution.
fn find_rgb(headers: &[exr::meta::header::Header]) -> Option<(usize, [usize; 3])> {
    for (part, header) in headers.iter().enumerate() {
        let names: Vec<String> = header.channels.list.iter().map(|c| c.name.to_string()).collect();
        let mut prefixes: Vec<&str> = names.iter().filter_map(|n| rgb_index(n).map(|(p, _)| p)).collect();
        prefixes.sort_by_key(|p| !p.is_empty());
        for prefix in prefixes {
            let mut found = [usize::MAX; 3];
            for (i, (c, name)) in header.channels.list.iter().zip(&names).enumerate() {
                if let Some((p, k)) = rgb_index(name) {
                    if p == prefix && c.sampling == exr::math::Vec2(1, 1) {
                        found[k] = i;
                    }
                }
            }
            if found.iter().all(|&i| i != usize::MAX) {
                return Some((part, found));
            }
        }
    }
    None
}

fn exr_error(path: &Path, e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::Io(io) => Error::io(path, io),
        other => Error::format(path, format!("EXR decoding failed: {other}")),
    }
}

/// Sums of the `factor` x `factor` boxes of the R, G, B channels, row-major, top row first.
fn decode_reduced(path: &Path, (w, h): (usize, usize), factor: usize) -> Result<Vec<Vec3>> {
    use exr::block::reader::ChunksReader;
    let file = std::io::BufReader::new(std::fs::File::open(path).map_err(|e| Error::io(path, e))?);
    let reader = exr::block::read(file, false).map_err(|e| exr_error(path, e))?;
    let Some((part, rgb)) = find_rgb(reader.headers()) else {
        return Err(Error::format(path, "EXR file has no part with full-resolution R, G and B channels"));
    };
    let header = &reader.headers()[part];
    // One block is decoded whole: a 16384x8192 tile is 1-2 GB however small the file.
    let block = header.max_block_pixel_size();
    let block_pixels = crate::budget::checked_product(
        "EXR block",
        &[block.0.min(w) as u64, block.1.min(h) as u64, header.channels.bytes_per_pixel as u64, BLOCK_COPIES],
    )?;
    crate::budget::check(&format!("{}: one EXR block ({}x{} pixels, decoded whole)", path.display(), block.0.min(w), block.1.min(h)), block_pixels)?;
    let channels = header.channels.clone();
    // The offset tables are read (and must be in the file) before the map is allocated: a
    // 300-byte header promising 16384x8192 pixels fails here, having allocated nothing large.
    let chunks = reader
        .filter_chunks(false, |_, tile, index| index.layer == part && tile.is_largest_resolution_level())
        .map_err(|e| exr_error(path, e))?;
    let (ow, oh) = (w.div_ceil(factor), h.div_ceil(factor));
    let n = crate::budget::check_elements::<[u8; DOME_BYTES_PER_PIXEL as usize]>(
        &format!("dome map {} ({w}x{h} read at {ow}x{oh})", path.display()),
        ow as u64 * oh as u64,
    )?;
    let mut sums = vec![Vec3::ZERO; n];
    let mut covered = 0u64;
    let mut blocks = chunks.sequential_decompressor(false);
    while let Some(block) = blocks.decompress_next_block() {
        let block = block.map_err(|e| exr_error(path, e))?;
        // The chunk says where it goes; a hostile file may point it anywhere.
        if block.index.layer != part || block.index.level != exr::math::Vec2(0, 0) {
            continue;
        }
        for line in block.lines(&channels) {
            let Some(c) = rgb.iter().position(|&i| i == line.location.channel) else { continue };
            let (x0, y) = (line.location.position.x(), line.location.position.y());
            let count = line.location.sample_count;
            if y >= h || x0.checked_add(count).is_none_or(|end| end > w) {
                return Err(Error::format(path, format!("EXR block line at ({x0}, {y}) lies outside the {w}x{h} data window")));
            }
            let row = (y / factor) * ow;
            let mut add = |i: usize, v: f32| sums[row + (x0 + i) / factor][c] += v;
            let bad = |_| Error::format(path, "EXR line shorter than its channel type");
            match channels.list[line.location.channel].sample_type {
                SampleType::F16 => {
                    for (i, v) in line.read_samples::<f16>().enumerate() {
                        add(i, v.map_err(bad)?.to_f32());
                    }
                }
                SampleType::F32 => {
                    for (i, v) in line.read_samples::<f32>().enumerate() {
                        add(i, v.map_err(bad)?);
                    }
                }
                SampleType::U32 => {
                    for (i, v) in line.read_samples::<u32>().enumerate() {
                        add(i, v.map_err(bad)? as f32);
                    }
                }
            }
            if c == 0 {
                covered += count as u64;
            }
        }
    }
    if covered < w as u64 * h as u64 {
        return Err(Error::format(path, format!("EXR file is truncated: {covered} of {} pixels present", w as u64 * h as u64)));
    }
    Ok(sums)
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
    write_layer(path, layer)
}

/// Encodes one layer in memory, then writes it with [`super::files::write_file_atomic`]: a full
/// disk or a missing folder is an `Error::Io` and leaves the previous file as it was. (`exr`'s own `to_file` also deletes the path when a
/// write fails, which must not happen to `/dev/full` or to a file the user pointed us at.)
pub fn write_layer(path: &Path, layer: Layer<AnyChannels<FlatSamples>>) -> Result<()> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr::image::Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| Error::format(path, format!("encoding EXR failed: {e}")))?;
    super::files::write_file_atomic(path, bytes.get_ref())
}

/// Reads back the RGBA of an EXR written by `write_image` (tests, `compare`).
pub fn read_rgba(path: &Path) -> Result<Image> {
    let (w, h) = check_header(path)?;
    // Decoded whole (an image to compare is wanted at full size): the pixels and exr's copy.
    crate::budget::check_elements::<[Vec4; 2]>(&format!("EXR image {} ({w}x{h})", path.display()), w as u64 * h as u64)?;
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
