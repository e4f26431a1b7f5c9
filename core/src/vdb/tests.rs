//! Fixture files written by OpenVDB 10 and Blender 5 (numbers from `shared/fixtures/README.md`,
//! which are OpenVDB's own), writer round trips, and hostile input: truncation, mutation,
//! lying sizes. Every hostile case runs under `catch_unwind` to prove it cannot panic.

use crate::solvers::SolveCtx;
use crate::solvers::Solver;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use glam::{Affine3A, IVec3, Vec3};

use super::bytes::Writer;
use super::header::{MAGIC, WRITE_FILE_VERSION};
use super::*;
use crate::medium::{DensityGridBuilder, GridLimits};

fn fixtures() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures");
    assert!(p.is_dir(), "fixtures not found at {} (shared/ must sit beside the repository)", p.display());
    p
}

fn all_fixture_files() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(fixtures().join("vdb"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "vdb"))
        .collect();
    v.sort();
    v.push(fixtures().join("blender_noise_cube/volumes/Volume.vdb"));
    v
}

fn scalar(s: &Option<Sum>) -> f64 {
    match s {
        Some(Sum::Scalar(v)) => *v,
        other => panic!("expected a scalar sum, got {other:?}"),
    }
}

/// (file, half, transform, active voxels, sum) from the fixture README.
const TABLE: &[(&str, bool, &str, u64, f64)] = &[
    ("vdb/fog_blosc_full.vdb", false, "UniformScaleMap", 2512, 1819.000),
    ("vdb/fog_blosc_half.vdb", true, "UniformScaleMap", 2512, 1818.922),
    ("vdb/unk_zip_full.vdb", false, "UniformScaleMap", 2512, 1819.000),
    ("vdb/mini_zip.vdb", false, "UniformScaleMap", 851, 510.645),
    ("vdb/mini_mask.vdb", false, "UniformScaleMap", 851, 510.645),
    ("vdb/affine_blosc_full.vdb", false, "AffineMap", 2512, 1819.000),
    ("vdb/roottile_blosc_full.vdb", false, "UniformScaleMap", 68719479248, 68719478555.000),
    ("vdb/vec3_and_density_blosc.vdb", false, "UniformScaleMap", 2512, 1819.000),
    ("blender_noise_cube/volumes/Volume.vdb", false, "UniformScaleTranslateMap", 64000, 32004.610),
];

#[test]
fn fixtures_match_openvdb_numbers() {
    for &(file, half, map, active, sum) in TABLE {
        let path = fixtures().join(file);
        let info = inspect(&path).unwrap_or_else(|e| panic!("{file}: {e}"));
        let g = info.grids.iter().find(|g| g.name == "density").unwrap_or_else(|| panic!("{file}: no density"));
        assert_eq!(g.value_type, "float", "{file}");
        assert_eq!(g.half, half, "{file}");
        assert_eq!(g.transform, map, "{file}");
        assert_eq!(g.active_voxels, Some(active), "{file}");
        let s = scalar(&g.sum);
        assert!((s - sum).abs() <= 5e-4 + sum.abs() * 1e-12, "{file}: sum {s} vs OpenVDB {sum}");
        eprintln!("{file}: active {} sum {s:.4} (OpenVDB: {active} {sum:.3})", g.active_voxels.unwrap());
    }
}

#[test]
fn fixture_details() {
    let f = fixtures();
    // Fog box: bbox and class.
    let info = inspect(&f.join("vdb/fog_blosc_full.vdb")).unwrap();
    let g = &info.grids[0];
    assert_eq!(info.file_version, 224);
    assert_eq!(g.class, "fog volume");
    assert_eq!(g.bbox_min, Some([0, 0, 0]));
    assert_eq!(g.bbox_max, Some([1031, 9, 9]));
    assert!((g.index_to_world[0][0] - 0.1).abs() < 1e-12);
    let unk = inspect(&f.join("vdb/unk_zip_full.vdb")).unwrap();
    assert_eq!(unk.grids[0].class, "unknown");
    assert!(unk.grids[0].compression.starts_with("zip"));

    // AffineMap: rotated 0.3 rad about Z, scale 0.1.
    let (grid, xf) = load_density(&f.join("vdb/affine_blosc_full.vdb"), None, GridLimits::default()).unwrap();
    let want = Affine3A::from_rotation_z(0.3) * Affine3A::from_scale(Vec3::splat(0.1));
    assert!(xf.abs_diff_eq(want, 1e-6), "{xf:?}");
    assert_eq!(grid.voxel(IVec3::new(1030, 5, 5)), 2.0, "level-1 tile");

    // vec3 grid: listed with its statistics, refused as density; None picks "density".
    let path = f.join("vdb/vec3_and_density_blosc.vdb");
    let info = inspect(&path).unwrap();
    let v = info.grids.iter().find(|g| g.name == "velocity").unwrap();
    assert_eq!(v.value_type, "vec3s");
    assert_eq!(v.active_voxels, Some(10));
    match &v.sum {
        Some(Sum::Vector(s)) => assert!((s[0] - 10.0).abs() < 1e-9, "{s:?}"),
        other => panic!("{other:?}"),
    }
    let e = load_density(&path, Some("velocity"), GridLimits::default()).unwrap_err().to_string();
    assert!(e.contains("vec3s") && e.contains("not float"), "{e}");
    let e = load_density(&path, Some("nope"), GridLimits::default()).unwrap_err().to_string();
    assert!(e.contains("no grid named") && e.contains("velocity"), "{e}");
    let (g, _) = load_density(&path, None, GridLimits::default()).unwrap();
    assert!((g.sum_and_count_nonzero().0 - 1819.0).abs() < 1e-3);

    // A 4096^3 root tile: a clear error before any allocation.
    let e = load_density(&f.join("vdb/roottile_blosc_full.vdb"), None, GridLimits::default()).unwrap_err();
    assert!(matches!(e, Error::TooLarge(_)), "{e}");
}

#[test]
fn fixtures_load_as_density_with_the_same_sums() {
    for &(file, half, _, _, sum) in TABLE {
        if file.contains("roottile") {
            continue;
        }
        let (g, _) = load_density(&fixtures().join(file), None, GridLimits::default()).unwrap();
        let (s, _) = g.sum_and_count_nonzero();
        assert!((s - sum).abs() < 5e-3 + sum * 1e-6, "{file}: {s} vs {sum}");
        if half {
            // Every value is a half: converting back and forth changes nothing.
            g.for_each_brick(|_, b| {
                if let crate::medium::grid::BrickRef::Dense(v) = b {
                    for x in v.iter() {
                        assert_eq!(half::f16::from_f32(*x).to_f32(), *x);
                    }
                }
            });
        }
    }
    // Blender's cube: 40^3 voxels, UniformScaleTranslateMap.
    let (g, xf) = load_density(&fixtures().join("blender_noise_cube/volumes/Volume.vdb"), None, GridLimits::default()).unwrap();
    let (lo, hi) = g.bbox();
    assert_eq!(hi - lo, IVec3::splat(39));
    assert!(xf.translation.length() > 0.0);
}

fn sample_grid() -> DensityGrid {
    let mut b = DensityGridBuilder::new(GridLimits::default());
    let mut state = 12345u64;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    for _ in 0..3000 {
        let p = IVec3::new((rnd() % 300) as i32 - 150, (rnd() % 60) as i32 - 7, (rnd() % 40) as i32 + 4000);
        // Values exact in half precision so that half round trips compare exactly too.
        let v = (rnd() % 1000) as f32 / 64.0;
        b.set(p, v).unwrap();
    }
    b.fill_tile(IVec3::new(512, 8, 4096), 16, 1.5).unwrap();
    b.build().unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volscatter-vdb-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn writer_round_trips_every_mode() {
    let g = sample_grid();
    let xf = Affine3A::from_translation(Vec3::new(1.0, -2.0, 3.0)) * Affine3A::from_scale(Vec3::splat(0.05));
    let (want_sum, want_count) = g.sum_and_count_nonzero();
    for half in [false, true] {
        for compression in [VdbCompression::None, VdbCompression::Zip] {
            let path = tmp(&format!("rt_{half}_{compression:?}.vdb"));
            let opts = WriteOptions { half, compression, ..Default::default() };
            write_float_grid(&path, "density", &g, xf, &opts).unwrap();
            let info = inspect(&path).unwrap();
            let gi = &info.grids[0];
            assert_eq!(gi.half, half);
            assert_eq!(gi.transform, "UniformScaleTranslateMap");
            assert_eq!(gi.active_voxels, Some(want_count));
            assert!((scalar(&gi.sum) - want_sum).abs() < 1e-6 * want_sum);
            let (back, bxf) = load_density(&path, None, GridLimits::default()).unwrap();
            assert!(bxf.abs_diff_eq(xf, 1e-7));
            assert_eq!(back.bbox(), g.bbox());
            let (lo, hi) = g.bbox();
            for z in lo.z..=hi.z {
                for y in lo.y..=hi.y {
                    for x in (lo.x..=hi.x).step_by(3) {
                        let p = IVec3::new(x, y, z);
                        assert_eq!(back.voxel(p), g.voxel(p), "{p} half={half} {compression:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn writer_dense_rgb_and_affine() {
    let dims = [13u32, 9, 20];
    let n = (dims[0] * dims[1] * dims[2]) as usize;
    let data: Vec<Vec3> = (0..n).map(|i| Vec3::new(i as f32 * 0.25, if i % 3 == 0 { 0.0 } else { 1.0 }, -(i as f32))).collect();
    let xf = Affine3A::from_rotation_y(0.7) * Affine3A::from_scale(Vec3::new(0.1, 0.2, 0.3));
    let path = tmp("rgb.vdb");
    write_rgb_grids(&path, "scatter", dims, &data, xf, &WriteOptions::default()).unwrap();
    let info = inspect(&path).unwrap();
    let names: Vec<&str> = info.grids.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["scatter_r", "scatter_g", "scatter_b"]);
    for (c, g) in info.grids.iter().enumerate() {
        assert_eq!(g.transform, "AffineMap");
        let want: f64 = data.iter().map(|v| v[c] as f64).sum();
        let count = data.iter().filter(|v| v[c] != 0.0).count() as u64;
        assert_eq!(g.active_voxels, Some(count));
        assert!((scalar(&g.sum) - want).abs() < 1e-6 * want.abs().max(1.0), "{c}");
        assert_eq!(g.bbox_max, Some([12, 8, 19]));
    }
    let f = VdbFile::open(&path, 1 << 30).unwrap();
    let (gg, gxf) = f.load_float_grid(1, GridLimits::default()).unwrap();
    assert!(gxf.abs_diff_eq(xf, 1e-6));
    assert_eq!(gg.voxel(IVec3::new(5, 2, 7)), 1.0);
    assert_eq!(gg.voxel(IVec3::new(0, 0, 0)), 0.0);
    // An empty grid is a valid file with no voxels.
    let empty = tmp("empty.vdb");
    write_float_grid(&empty, "density", &DensityGrid::empty(), xf, &WriteOptions::default()).unwrap();
    let info = inspect(&empty).unwrap();
    assert_eq!(info.grids[0].active_voxels, Some(0));
    assert!(load_density(&empty, None, GridLimits::default()).unwrap().0.is_empty());
    // Half precision saturates instead of writing inf.
    let big = [1.0e6f32; 8];
    let hp = tmp("big_half.vdb");
    let opts = WriteOptions { half: true, ..Default::default() };
    write_dense_float_grids(&hp, &[DenseFloat { name: "d", dims: [2, 2, 2], values: &big }], xf, &opts).unwrap();
    assert_eq!(scalar(&inspect(&hp).unwrap().grids[0].sum), 8.0 * 65504.0);
    // Bad input to the writer.
    assert!(write_rgb_grids(&path, "s", [2, 2, 2], &data[..7], xf, &WriteOptions::default()).is_err());
    let bad = vec![f32::NAN; 8];
    assert!(write_dense_float_grids(&path, &[DenseFloat { name: "d", dims: [2, 2, 2], values: &bad }], xf, &WriteOptions::default()).is_err());
}

/// Reads everything a file holds the way vdb-info and the scene loader do.
fn exercise(bytes: Vec<u8>) -> Result<()> {
    let f = VdbFile::from_bytes(bytes, Path::new("fuzz.vdb"))?;
    let limits = GridLimits { max_bytes: 64 << 20, max_extent_voxels: 1 << 27 };
    let mut first_err = None;
    for i in 0..f.grids.len() {
        if let Err(e) = f.grid_info(i) {
            first_err.get_or_insert(e);
        }
        if let Err(e) = f.load_float_grid(i, limits) {
            first_err.get_or_insert(e);
        }
    }
    first_err.map_or(Ok(()), Err)
}

fn no_panic(bytes: Vec<u8>, what: &str) -> Result<()> {
    match catch_unwind(AssertUnwindSafe(|| exercise(bytes))) {
        Ok(r) => r,
        Err(_) => panic!("reader panicked on {what}"),
    }
}

#[test]
fn truncation_at_every_64th_is_an_error() {
    for path in all_fixture_files() {
        let data = std::fs::read(&path).unwrap();
        for k in 0..64 {
            let cut = data.len() * k / 64;
            let r = no_panic(data[..cut].to_vec(), &format!("{} cut at {cut}", path.display()));
            assert!(r.is_err(), "{} cut at {cut} of {} read fine", path.display(), data.len());
        }
    }
}

#[test]
fn random_mutations_never_panic() {
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let files = all_fixture_files();
    let (mut ok, mut err) = (0, 0);
    // 400 rounds in the normal suite; VOLSCATTER_VDB_FUZZ_ROUNDS=N runs a longer campaign.
    let rounds: usize = std::env::var("VOLSCATTER_VDB_FUZZ_ROUNDS").ok().and_then(|v| v.parse().ok()).unwrap_or(400);
    for round in 0..rounds {
        let path = &files[round % files.len()];
        let mut data = std::fs::read(path).unwrap();
        let n = 1 + (rnd() % 8) as usize;
        // Odd rounds aim at the first 2 KiB: header, metadata, descriptor, transform, root,
        // the start of the topology; even rounds anywhere.
        let span = if round % 2 == 1 { data.len().min(2048) } else { data.len() };
        for _ in 0..n {
            let i = (rnd() % span as u64) as usize;
            match rnd() % 4 {
                0 => data[i] = rnd() as u8,
                1 => data[i] ^= 1 << (rnd() % 8),
                2 => data[i] = 0xff,
                _ => {
                    // A 4- or 8-byte field set to a large value.
                    let v = [0x7fu8, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f];
                    let m = (data.len() - i).min(8);
                    data[i..i + m].copy_from_slice(&v[..m]);
                }
            }
        }
        match no_panic(data, &format!("mutation round {round} of {}", path.display())) {
            Ok(()) => ok += 1,
            Err(_) => err += 1,
        }
    }
    eprintln!("mutations: {ok} read, {err} refused, 0 panics");
}

/// A minimal valid file around one hand-made tree body, for crafting bad counts.
fn craft(tree: impl FnOnce(&mut Writer), compression: u32, grid_type: &str) -> Vec<u8> {
    let mut w = Writer::default();
    w.bytes(&MAGIC.to_le_bytes());
    w.u32(WRITE_FILE_VERSION);
    w.u32(10);
    w.u32(0);
    w.u8(1);
    w.bytes(&[b'0'; 36]);
    w.u32(0);
    w.i32(1);
    w.string("density");
    w.string(grid_type);
    w.string("");
    let at = w.pos();
    w.bytes(&[0; 24]);
    let grid_pos = w.pos();
    w.u32(compression);
    w.u32(0);
    super::transform::write_transform(&mut w, Affine3A::IDENTITY);
    tree(&mut w);
    let end = w.pos();
    w.patch_i64(at, grid_pos as i64);
    w.patch_i64(at + 8, grid_pos as i64);
    w.patch_i64(at + 16, end as i64);
    w.buf
}

#[test]
fn crafted_counts_and_sizes_are_refused() {
    use super::header::{COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC, COMPRESS_ZIP};
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("huge root counts", craft(|w| { w.i32(1); w.f32(0.0); w.u32(u32::MAX); w.u32(u32::MAX); }, 0, "Tree_float_5_4_3")),
        ("two buffers", craft(|w| { w.i32(2); }, 0, "Tree_float_5_4_3")),
        ("unaligned root child", craft(|w| { w.i32(1); w.f32(0.0); w.u32(0); w.u32(1); w.i32(5); w.i32(0); w.i32(0); w.bytes(&[0; 8192]); }, 0, "Tree_float_5_4_3")),
        ("duplicate root tile", craft(|w| { w.i32(1); w.f32(0.0); w.u32(2); w.u32(0); for _ in 0..2 { w.i32(0); w.i32(0); w.i32(0); w.f32(1.0); w.u8(1);} }, 0, "Tree_float_5_4_3")),
        ("internal node all children, no bytes", craft(|w| { w.i32(1); w.f32(0.0); w.u32(0); w.u32(1); w.i32(0); w.i32(0); w.i32(0); w.bytes(&[0xff; 4096]); w.bytes(&[0; 4096]); w.u8(6); w.bytes(&[0; 32768 * 4]); }, 0, "Tree_float_5_4_3")),
        ("zip size past the end", craft(|w| { w.i32(1); w.f32(0.0); w.u32(0); w.u32(1); w.i32(0); w.i32(0); w.i32(0); w.bytes(&[0; 8192]); w.u8(6); w.i64(1 << 40); }, COMPRESS_ZIP, "Tree_float_5_4_3")),
        ("blosc chunk that lies", craft(|w| {
            w.i32(1); w.f32(0.0); w.u32(0); w.u32(1); w.i32(0); w.i32(0); w.i32(0); w.bytes(&[0; 8192]); w.u8(6);
            let mut chunk = super::blosc::blosc_compress(&vec![0u8; 32768 * 4]);
            chunk[4..8].copy_from_slice(&(u32::MAX - 64).to_le_bytes());
            w.i64(chunk.len() as i64); w.bytes(&chunk);
        }, COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK, "Tree_float_5_4_3")),
        ("bad node metadata", craft(|w| { w.i32(1); w.f32(0.0); w.u32(0); w.u32(1); w.i32(0); w.i32(0); w.i32(0); w.bytes(&[0; 8192]); w.u8(42); }, 0, "Tree_float_5_4_3")),
        ("NaN tile", craft(|w| { w.i32(1); w.f32(0.0); w.u32(1); w.u32(0); w.i32(0); w.i32(0); w.i32(0); w.f32(f32::NAN); w.u8(1); }, 0, "Tree_float_5_4_3")),
        ("half int grid", craft(|w| { w.i32(1); w.i32(0); w.u32(0); w.u32(0); }, 0, "Tree_int32_5_4_3_HalfFloat")),
        ("unknown compression", craft(|w| { w.i32(1); }, 0x40, "Tree_float_5_4_3")),
        ("level set background", craft(|w| { w.i32(1); w.f32(0.3); w.u32(0); w.u32(0); }, 0, "Tree_float_5_4_3")),
    ];
    for (what, bytes) in cases {
        let r = no_panic(bytes, what);
        assert!(r.is_err(), "{what} was accepted");
        eprintln!("{what}: {}", r.unwrap_err());
    }
    // Magic, version, offsets.
    let good = std::fs::read(fixtures().join("vdb/mini_zip.vdb")).unwrap();
    let mut bad = good.clone();
    bad[..8].copy_from_slice(b"NOTAVDB!");
    assert!(no_panic(bad, "magic").unwrap_err().to_string().contains("magic"));
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(&213u32.to_le_bytes());
    assert!(no_panic(bad, "old").unwrap_err().to_string().contains("too old"));
    assert!(no_panic(Vec::new(), "empty").is_err());
    // The file itself is fine.
    no_panic(good, "good").unwrap();
}

#[test]
fn not_a_file_and_limits() {
    let e = load_density(Path::new("/nonexistent/x.vdb"), None, GridLimits::default()).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
    let small = GridLimits { max_bytes: 1000, max_extent_voxels: 1 << 30 };
    let e = load_density(&fixtures().join("vdb/mini_zip.vdb"), None, small).unwrap_err();
    assert!(matches!(e, Error::TooLarge(_)), "{e}");
}

#[test]
fn blender_vdb_scene_renders_with_the_reference_solver() {
    // Blender's Volume Cube (40^3, world [-1, 1]^3), read through the scene loader.
    let json = r#"{
      "format": 1,
      "medium": {"vdb": "volumes/Volume.vdb", "density_scale": 2.0, "albedo": 0.9, "g": 0.3},
      "lights": [{"type": "distant", "direction": [0.3, 0.5, -0.8], "irradiance": 3.0}],
      "camera": {"position": [0, -6, 0.5], "look_at": [0, 0, 0], "up": [0, 0, 1],
                 "fov_deg": 30, "width": 24, "height": 24},
      "solver": {"name": "reference", "spp": 4}
    }"#;
    let scene = crate::Scene::from_json_str(json, &fixtures().join("blender_noise_cube")).unwrap();
    let (lo, hi) = scene.medium.world_bounds();
    assert!(lo.cmpgt(Vec3::splat(-1.2)).all() && hi.cmplt(Vec3::splat(1.2)).all(), "{lo} {hi}");
    let solver = crate::solvers::reference::Reference::from_settings(&scene.solver).unwrap();
    let mut timings = crate::stages::Timings::default();
    let img = solver.render_image(&scene, &mut SolveCtx::new(&crate::stages::NoProgress), false, &mut timings).expect("the reference renders images").unwrap();
    let s = img.stats();
    assert_eq!(s.non_finite_pixels, 0);
    assert!(s.mean_alpha > 0.1 && s.mean_alpha < 1.0, "{s:?}");
    assert!(s.mean_rgb[0] > 0.0, "{s:?}");
}

/// Read throughput of `load_density` and `inspect` on the file named by VOLSCATTER_VDB_BENCH
/// (run with `--ignored --nocapture`, in release).
#[test]
#[ignore]
fn bench_read_file() {
    let Ok(path) = std::env::var("VOLSCATTER_VDB_BENCH") else {
        eprintln!("set VOLSCATTER_VDB_BENCH=FILE.vdb");
        return;
    };
    let path = PathBuf::from(path);
    let bytes = std::fs::metadata(&path).unwrap().len() as f64;
    type Reader = fn(&Path) -> Result<u64>;
    let readers: [(&str, Reader); 2] = [
        ("load_density", |p| load_density(p, None, GridLimits::default()).map(|(g, _)| g.sum_and_count_nonzero().1)),
        ("inspect", |p| inspect(p).map(|i| i.grids[0].active_voxels.unwrap_or(0))),
    ];
    for (what, f) in readers {
        let mut best = f64::MAX;
        let mut voxels = 0;
        for _ in 0..5 {
            let t = std::time::Instant::now();
            voxels = f(&path).unwrap();
            best = best.min(t.elapsed().as_secs_f64());
        }
        eprintln!(
            "{what}: {:.1} ms, {:.0} MB/s, {:.1} Mvoxels/s ({voxels} voxels, {:.1} MB)",
            best * 1e3,
            bytes / best / 1e6,
            voxels as f64 / best / 1e6,
            bytes / 1e6
        );
    }
}
