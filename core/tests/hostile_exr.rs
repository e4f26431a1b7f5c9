//! Issue 22's hostile EXR dome maps, built here (small) and read under a counting allocator: the
//! peak of live bytes during a read is what would have aborted the host ("memory allocation of
//! N bytes failed"), so it is asserted directly. Its own test binary: the allocator counts every
//! allocation of the process, and nextest runs each test in a process of its own.

mod counting_alloc;

use std::path::{Path, PathBuf};

use counting_alloc::peak_during;

use volscatter_core::io::exr::{read_latlong, write_image};
use volscatter_core::Error;

const MIB: usize = 1 << 20;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vs-hostile-exr-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus/exr")
}

/// Overwrites the value of attribute `name` of type `ty` (little-endian 32-bit words).
fn patch_attribute(bytes: &mut [u8], name: &str, ty: &str, words: &[u32]) {
    let key = [name.as_bytes(), b"\0", ty.as_bytes(), b"\0"].concat();
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap_or_else(|| panic!("attribute {name}")) + key.len() + 4;
    for (i, w) in words.iter().enumerate() {
        bytes[at + 4 * i..at + 4 * i + 4].copy_from_slice(&w.to_le_bytes());
    }
}

/// A valid small EXR whose header is then made to promise 16384x8192 pixels. With `tile`, the
/// file is tiled with one tile covering the whole window (the 783 KB case's layout).
fn huge_header(tile: bool) -> Vec<u8> {
    use exr::prelude::*;
    let dir = temp_dir("src");
    let path = dir.join(if tile { "tile.exr" } else { "scan.exr" });
    if tile {
        let pixels = SpecificChannels::rgb(|_: Vec2<usize>| (0.5f32, 0.5f32, 0.5f32));
        let encoding = Encoding { compression: Compression::ZIP16, blocks: Blocks::Tiles(Vec2(16, 8)), line_order: LineOrder::Increasing };
        exr::image::Image::from_layer(Layer::new((16, 8), LayerAttributes::default(), encoding, pixels)).write().to_file(&path).unwrap();
    } else {
        let mut img = volscatter_core::Image::new(16, 8);
        img.rgba.fill(glam::Vec4::ONE);
        write_image(&path, &img).unwrap();
    }
    let mut bytes = std::fs::read(&path).unwrap();
    for window in ["dataWindow", "displayWindow"] {
        patch_attribute(&mut bytes, window, "box2i", &[0, 0, 16383, 8191]);
    }
    if tile {
        patch_attribute(&mut bytes, "tiles", "tiledesc", &[16384, 8192]);
    }
    bytes
}

/// Issue 22: "a 313-byte EXR header reaching 1.6 GB before it is refused". The header promises
/// 16384x8192 scanlines; the file holds one block. The offset table is read (and found short)
/// before the map is allocated, so the refusal costs little: 32 MiB bounds exr's header and
/// table buffers with room to spare (the old read allocated 1.5 GiB first).
#[test]
fn header_promising_a_huge_image_is_refused_before_allocating() {
    let path = corpus().join("header_16384x8192_scanlines.exr");
    let (res, peak) = peak_during(|| read_latlong(&path));
    let e = res.unwrap_err();
    assert!(matches!(e, Error::Format { .. } | Error::Io { .. }), "{e:?}");
    assert!(peak < 32 * MIB, "peak {} MiB while refusing {e}", peak / MIB);
}

/// Issue 22: a ZIP EXR holding one 16384x8192 tile (3-4.7 GB decoded). One block is decoded
/// whole, so the block itself is checked against the budget: with a 1 GiB budget the 4.5 GiB
/// (RGB f32 x 3 working copies) block is refused by name, before anything large is allocated.
#[test]
fn one_huge_tile_is_refused_against_the_budget() {
    volscatter_core::budget::set_budget(Some(1 << 30));
    let path = corpus().join("single_tile_16384x8192.exr");
    let (res, peak) = peak_during(|| read_latlong(&path));
    let e = res.unwrap_err();
    assert!(matches!(&e, Error::TooLarge(m) if m.contains("EXR block") && m.contains("16384x8192")), "{e:?}");
    assert!(peak < 32 * MIB, "peak {} MiB while refusing {e}", peak / MIB);
}

/// Issue 22: the same size as scanlines (pop's dome importance map reached 1.6 GB). A real file
/// of 16384x8192 half-float RGB (all 1.0) is written block by block here, then read at
/// 4096x2048: the reduced map, its sampling tables and one 16-line block fit in 400 MiB, where
/// decoding it whole took 1.5 GiB for the pixels alone. Every box averages 1.0 exactly.
#[test]
fn huge_scanline_dome_is_read_reduced_within_bounded_memory() {
    use exr::prelude::*;
    let dir = temp_dir("scan");
    let path = dir.join("huge_scanlines.exr");
    {
        let channels = ["B", "G", "R"].map(|n| exr::meta::attribute::ChannelDescription::new(n, SampleType::F16, true));
        let header = exr::meta::header::Header::new("sky".into(), (16384, 8192), channels.into_iter().collect())
            .with_encoding(Compression::ZIP16, exr::meta::BlockDescription::ScanLines, LineOrder::Increasing);
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let one = f16::from_f32(1.0).to_bits().to_ne_bytes();
        exr::block::write(file, std::iter::once(header).collect(), true, |meta, writer| {
            use exr::block::writer::ChunksWriter;
            let mut compressor = writer.sequential_blocks_compressor(&meta);
            for (i, block) in meta.collect_ordered_block_data(|index| one.repeat(index.pixel_size.area() * 3)) {
                compressor.compress_block(i, block)?;
            }
            Ok(())
        })
        .unwrap();
    }
    let file_size = std::fs::metadata(&path).unwrap().len();
    assert!(file_size < 4 << 20, "the hostile file is small: {file_size} bytes");
    let (map, peak) = peak_during(|| read_latlong(&path).unwrap());
    assert_eq!((map.width, map.height), (4096, 2048));
    assert!(map.pixels.iter().all(|p| *p == glam::Vec3::ONE), "a box of 1.0 averages to 1.0");
    assert!(peak < 400 * MIB, "peak {} MiB", peak / MIB);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Regenerates the EXR files of tests/corpus/exr (`--run-ignored only`); they are committed.
#[test]
#[ignore]
fn write_corpus() {
    std::fs::write(corpus().join("header_16384x8192_scanlines.exr"), huge_header(false)).unwrap();
    std::fs::write(corpus().join("single_tile_16384x8192.exr"), huge_header(true)).unwrap();
}
