//! `load_float_grid_filtered` (filter.rs): read through the file's window it equals the same
//! filter over the file in memory to the bit, and the whole load's voxels averaged cell by cell
//! within f32 rounding; its read window stays at one window; truncated files are errors.

use std::path::{Path, PathBuf};

use glam::IVec3;

use super::*;
use crate::medium::GridLimits;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volscatter-filter-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The mean of the whole grid's voxels over each coarse cell of `report`'s lattice, and the
/// largest voxel (the scale of the tolerance).
fn whole_box_filtered(whole: &DensityGrid, report: &FilterReport) -> (Vec<f32>, f32) {
    let f = report.factor;
    let c0 = report.fine_box.0.as_ivec3().div_euclid(IVec3::splat(f));
    let d = report.coarse_dims;
    let mut out = Vec::new();
    for z in 0..d.z {
        for y in 0..d.y {
            for x in 0..d.x {
                let c = (c0 + IVec3::new(x, y, z)) * f;
                let mut s = 0.0f64;
                for k in 0..f {
                    for j in 0..f {
                        for i in 0..f {
                            s += whole.voxel(c + IVec3::new(i, j, k)) as f64;
                        }
                    }
                }
                out.push((s / (f as f64).powi(3)) as f32);
            }
        }
    }
    (out, whole.max_value())
}

fn coarse_values(g: &DensityGrid, report: &FilterReport) -> Vec<f32> {
    let c0 = report.fine_box.0.as_ivec3().div_euclid(IVec3::splat(report.factor));
    let d = report.coarse_dims;
    let mut out = Vec::new();
    for z in 0..d.z {
        for y in 0..d.y {
            for x in 0..d.x {
                out.push(g.voxel(c0 + IVec3::new(x, y, z)));
            }
        }
    }
    out
}

fn res(cells: u32) -> MaxResolution {
    MaxResolution::new(cells).unwrap()
}

/// `max_resolution` out of 2..=4096 is refused with the range and the value (it was clamped
/// into range by the filter, and its range written out in three places), and both ends of the
/// range are taken: at 2 the plume is 2 cells along its longest side.
#[test]
fn max_resolution_out_of_range_is_refused_not_clamped() {
    for bad in [0, 1, 4097, u32::MAX] {
        let why = MaxResolution::new(bad).unwrap_err();
        assert!(why.contains("2..=4096") && why.contains(&bad.to_string()), "{bad}: {why}");
    }
    assert_eq!(MaxResolution::new(4096).map(MaxResolution::cells), Ok(4096));
    let dir = temp_dir("range");
    let (plume, xf) = crate::medium::procedural::plume(16, GridLimits::default()).unwrap();
    let p = dir.join("plume.vdb");
    write_float_grid(&p, "density", &plume, xf, &WriteOptions::default()).unwrap();
    let (_, _, r) = load_density_filtered(&p, None, res(2), GridLimits::default()).unwrap();
    assert_eq!(r.coarse_dims.max_element(), 2, "{r:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A transform past f32's range (a scale of 1e30: its determinant overflows) is the whole
/// load's error in the filtered load (empty grid too) and in `medium_size`, which sizes a
/// medium that would not load (it returned a size).
#[test]
fn a_transform_out_of_f32_range_is_refused_everywhere() {
    let dir = temp_dir("xf");
    let (plume, _) = crate::medium::procedural::plume(16, GridLimits::default()).unwrap();
    let huge = glam::Affine3A::from_scale(glam::Vec3::splat(1e30));
    for (name, grid) in [("plume", plume), ("empty", DensityGrid::empty())] {
        let p = dir.join(format!("{name}.vdb"));
        write_float_grid(&p, "density", &grid, huge, &WriteOptions::default()).unwrap();
        let file = VdbFile::open(&p, u64::MAX).unwrap();
        let whole = file.load_float_grid(0, GridLimits::default()).unwrap_err().to_string();
        assert!(whole.contains("out of single-precision range"), "{name}: {whole}");
        let filtered = file.load_float_grid_filtered(0, res(8), GridLimits::default()).unwrap_err().to_string();
        assert_eq!(filtered, whole, "{name}");
        if name == "plume" {
            for m in [None, Some(res(8))] {
                let e = file.medium_size(0, m).unwrap_err().to_string();
                assert_eq!(e, whole, "{name} {m:?}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Filtered (from disk) against the whole load of `path`, at `max_resolution`; returns the
/// report. Tolerance: the two sum the same f32 values in f64 in different orders, so their
/// means differ by f64 rounding, well under one f32 ulp: 1e-6 of the largest density.
fn check_file(path: &Path, max_resolution: u32) -> Option<FilterReport> {
    let file = VdbFile::open(path, u64::MAX).unwrap();
    let i = file.find_density_grid(None).ok()?;
    let Ok((whole, xf)) = file.load_float_grid(i, GridLimits::default()) else { return None };
    let (coarse, cxf, report) = file.load_float_grid_filtered(i, res(max_resolution), GridLimits::default()).unwrap();
    if whole.is_empty() {
        assert!(coarse.is_empty(), "{}", path.display());
        return Some(report);
    }
    assert!(report.coarse_dims.max_element() as u32 <= max_resolution, "{}: {report:?}", path.display());
    let (want, scale) = whole_box_filtered(&whole, &report);
    let got = coarse_values(&coarse, &report);
    let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst <= 1e-6 * scale, "{}: worst {worst} of {scale}", path.display());
    // A coarse cell's centre is the centre of its fine voxels.
    let f = report.factor as f32;
    let c = report.fine_box.0.as_ivec3().div_euclid(IVec3::splat(report.factor)).as_vec3();
    let fine_centre = c * f + glam::Vec3::splat(0.5 * (f - 1.0));
    assert!((cxf.transform_point3(c) - xf.transform_point3(fine_centre)).length() < 1e-4 * xf.transform_vector3(glam::Vec3::ONE).length() * f);
    // In memory, the same filter gives the same grid to the bit.
    let mem = VdbFile::from_bytes(std::fs::read(path).unwrap(), path).unwrap();
    let (m, mxf, mreport) = mem.load_float_grid_filtered(i, res(max_resolution), GridLimits::default()).unwrap();
    assert_eq!(coarse_values(&m, &report).iter().map(|v| v.to_bits()).collect::<Vec<_>>(), got.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
    assert_eq!((mxf, mreport.peak_window_bytes), (cxf, 0));
    assert_eq!(FilterReport { peak_window_bytes: report.peak_window_bytes, ..mreport }, report);
    Some(report)
}

#[test]
fn filtered_load_equals_the_whole_load_box_filtered_and_reads_one_window() {
    let dir = temp_dir("ours");
    let (plume, xf) = crate::medium::procedural::plume(64, GridLimits::default()).unwrap();
    for (k, (half, compression)) in [(false, VdbCompression::None), (false, VdbCompression::Zip), (true, VdbCompression::Zip)].into_iter().enumerate() {
        let p = dir.join(format!("plume{k}.vdb"));
        write_float_grid(&p, "density", &plume, xf, &WriteOptions { half, compression, ..Default::default() }).unwrap();
        let size = std::fs::metadata(&p).unwrap().len();
        for max_resolution in [7, 16, 64] {
            let r = check_file(&p, max_resolution).unwrap();
            eprintln!("{}: {size} bytes, max_resolution {max_resolution}: {r:?}", p.display());
            // One window of the reader, never the file (the uncompressed one is 3.6 windows).
            assert!(r.peak_window_bytes <= bytes::WINDOW, "{r:?}");
            assert!(k != 0 || size > 3 * bytes::WINDOW as u64, "{size}");
            assert!(r.leaves > 0);
        }
        // At the full resolution the filter is the identity: the whole load to the bit.
        let (full, _, r) = load_density_filtered(&p, None, res(1024), GridLimits::default()).unwrap();
        let (whole, _) = load_density(&p, None, GridLimits::default()).unwrap();
        assert_eq!(r.factor, 1);
        let (lo, hi) = whole.bbox();
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let c = IVec3::new(x, y, z);
                    assert_eq!(full.voxel(c).to_bits(), whole.voxel(c).to_bits(), "{c}");
                }
            }
        }
    }
    let fixtures = super::region_tests::files();
    if fixtures.is_empty() {
        eprintln!("SKIPPED the fixture files: shared/fixtures not found beside the repository");
    }
    for p in fixtures {
        let r = check_file(&p, 12);
        eprintln!("{}: {r:?}", p.display());
        if r.is_none() && p.file_name().is_some_and(|n| n == "roottile_blosc_full.vdb") {
            // Root tiles of 4096^3 voxels (12288 x 4096 x 4096 here), which the whole load refuses (over the grid
            // limits): filtered, it is 12^3 cells of its value at most.
            let (g, _, r) = load_density_filtered(&p, None, res(12), GridLimits::default()).unwrap();
            eprintln!("{}: filtered {r:?}, max {}", p.display(), g.max_value());
            assert!(r.coarse_dims.max_element() <= 12 && r.factor >= 4096 / 12, "{r:?}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every cut of the file (each 1/40th, and the last byte) is an error naming the file, never a
/// panic or a grid.
#[test]
fn truncated_files_are_clear_errors_when_filtered() {
    let dir = temp_dir("cut");
    let (plume, xf) = crate::medium::procedural::plume(32, GridLimits::default()).unwrap();
    let p = dir.join("plume.vdb");
    write_float_grid(&p, "density", &plume, xf, &WriteOptions { compression: VdbCompression::Zip, ..Default::default() }).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let cut = dir.join("cut.vdb");
    let n = bytes.len();
    for at in (0..40).map(|k| k * n / 40).chain([n - 1]) {
        std::fs::write(&cut, &bytes[..at]).unwrap();
        let e = load_density_filtered(&cut, None, res(8), GridLimits::default()).err().unwrap_or_else(|| panic!("cut at {at} of {n} loaded")).to_string();
        assert!(e.contains("cut.vdb"), "cut at {at}: {e}");
    }
    // The descriptor's offsets past the end: said so before any tree is read.
    std::fs::write(&cut, &bytes[..n - 100]).unwrap();
    let e = load_density_filtered(&cut, None, res(8), GridLimits::default()).unwrap_err().to_string();
    assert!(e.contains("past the end of the file"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// At most `max_resolution` cells along every axis, for boxes that do not start on a multiple
/// of the factor: max_resolution 2 on a 2^31-wide box starting at 8 gave 3 cells (issue 40).
#[test]
fn harden_the_lattice_never_exceeds_max_resolution() {
    use glam::I64Vec3;
    for (lo, width, m) in [(8i64, 1i64 << 31, 2u32), (8, (1 << 32) - 16, 2), (-5, 1 << 31, 3), (1, 1000, 7), (-3, 64, 4), (0, 64, 4), (7, 7, 2)] {
        let (f, _, dims) = super::filter::lattice(I64Vec3::splat(lo), I64Vec3::splat(lo + width), super::filter::MaxResolution::new(m).unwrap());
        assert!(dims.max_element() <= m as i64 && dims.min_element() >= 1, "lo {lo} width {width} m {m}: {dims} cells of {f}");
        assert!(f * dims.x >= width, "the cells cover the box");
    }
}
