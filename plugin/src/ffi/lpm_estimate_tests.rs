//! `vs_scene_lpm_estimate` on a sparse VDB with a 1024^3 index box and two leaves (the
//! fixture tests/python/fixtures/sparse_1024.vdb, which the add-on's tests use too: written
//! here by our VDB writer when missing or with `VOLSCATTER_BLESS=1`, and its content checked), and
//! its refusals: every bad argument is a status with a message, never a crash.

use std::ffi::{CStr, CString};
use std::path::PathBuf;

use glam::{Affine3A, IVec3, Vec3};
use volscatter_core::medium::{DensityGridBuilder, GridLimits};
use volscatter_core::solvers::lpm::{estimate, LpmSettings};
use volscatter_core::vdb::{write_float_grid, WriteOptions};

use super::*;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/python/fixtures/sparse_1024.vdb")
}

/// Two leaves of density 1 at opposite corners of 0..1024 (voxel 1/1024: a unit cube).
fn sparse_bytes() -> Vec<u8> {
    let mut b = DensityGridBuilder::new(GridLimits::default());
    for origin in [IVec3::ZERO, IVec3::splat(1016)] {
        b.set_leaf(origin, &[1.0; 512]).unwrap();
    }
    let grid = b.build().unwrap();
    let dir = std::env::temp_dir().join(format!("volscatter-lpm-estimate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("sparse.vdb");
    write_float_grid(&p, "density", &grid, Affine3A::from_scale(Vec3::splat(1.0 / 1024.0)), &WriteOptions::default()).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    bytes
}

fn estimate_of(scene: *mut VsScene, path: &str, max_resolution: u32, settings: Option<&str>) -> (VsStatus, VsLpmEstimate, String) {
    let path = CString::new(path).unwrap();
    let settings = settings.map(|s| CString::new(s).unwrap());
    let mut out = VsLpmEstimate { dense_bytes: 7, ..Default::default() };
    let st = unsafe {
        vs_scene_lpm_estimate(scene, path.as_ptr(), std::ptr::null(), std::ptr::null(), max_resolution, settings.as_ref().map_or(std::ptr::null(), |s| s.as_ptr()), &mut out)
    };
    let msg = unsafe { CStr::from_ptr(vs_scene_last_error(scene)) }.to_string_lossy().into_owned();
    (st, out, msg)
}

#[test]
fn lpm_estimate_of_a_sparse_1024_vdb_without_reading_its_voxels() {
    let path = fixture();
    if std::env::var_os("VOLSCATTER_BLESS").is_some() || !path.exists() {
        std::fs::write(&path, sparse_bytes()).unwrap();
    }
    // The file carries a fresh UUID each write: checked by content, not bytes.
    let size = volscatter_core::vdb::VdbFile::open(&path, 1 << 20).and_then(|f| f.medium_size(0, None)).unwrap().unwrap();
    assert_eq!((size.fine_box.0.to_array(), size.fine_box.1.to_array(), size.leaves), ([0; 3], [1024; 3], 2), "{}: rerun with VOLSCATTER_BLESS=1", path.display());
    assert!(std::fs::metadata(&path).unwrap().len() < 16 << 10, "a sparse file");
    let mut scene = std::ptr::null_mut();
    assert_eq!(unsafe { vs_scene_new(&mut scene) }, VsStatus::Ok);
    let p = path.to_str().unwrap();

    let (st, e, msg) = estimate_of(scene, p, 0, None);
    assert_eq!(st, VsStatus::Ok, "{msg}");
    assert_eq!(e.voxels, [1024; 3]);
    assert_eq!(e.dense_bytes, 4 << 30, "1024^3 floats");
    assert_eq!((e.medium_dims, e.medium_bytes), ([1024; 3], 4 << 30), "read whole");
    // The box widened by a voxel each side (Medium::index_bounds): a cube, 32 cells a side.
    assert_eq!(e.grid_dims, [32; 3]);
    let (lo, hi) = (Vec3::splat(-1.0 / 1024.0), Vec3::splat(1024.0 / 1024.0));
    let core = estimate::memory(lo, hi, &LpmSettings::default()).unwrap();
    assert_eq!((e.in_memory_bytes, e.out_of_core_bytes, e.scratch_bytes), (core.in_memory_bytes, core.out_of_core_bytes, core.scratch_bytes));

    // Box-filtered to 128: factor 8, 128^3 cells held; lpm out of core under 8 MiB.
    let budget = 8u64 << 20;
    let settings = format!(r#"{{"out_of_core": true, "memory_budget": {budget}, "first_order": "boundary", "grid_resolution": 64}}"#);
    let (st, e, msg) = estimate_of(scene, p, 128, Some(&settings));
    assert_eq!(st, VsStatus::Ok, "{msg}");
    assert_eq!((e.voxels, e.medium_dims, e.medium_bytes), ([1024; 3], [128; 3], 128 * 128 * 128 * 4));
    assert_eq!(e.grid_dims, [64; 3]);
    assert!(e.out_of_core_bytes > 0 && e.out_of_core_bytes <= budget, "{e:?}");
    assert!(e.in_memory_bytes > 5 * e.out_of_core_bytes, "the slab is a fraction of the whole: {e:?}");

    // Refusals: a status and a message, `*out` zeroed.
    let dir = std::env::temp_dir();
    let junk = dir.join(format!("volscatter-not-a-vdb-{}.vdb", std::process::id()));
    std::fs::write(&junk, b"garbage, not an OpenVDB file").unwrap();
    for (what, path, res, settings, want) in [
        ("missing file", "/nonexistent/cloud.vdb", 0, None, VsStatus::Io),
        ("not a VDB", junk.to_str().unwrap(), 0, None, VsStatus::Format),
        ("max_resolution 1", p, 1, None, VsStatus::InvalidArgument),
        ("max_resolution 4097", p, 4097, None, VsStatus::InvalidArgument),
        ("settings not JSON", p, 0, Some("{"), VsStatus::InvalidArgument),
        ("unknown setting", p, 0, Some(r#"{"grid_res": 3}"#), VsStatus::InvalidScene),
        ("invalid setting", p, 0, Some(r#"{"directions": 7}"#), VsStatus::InvalidScene),
    ] {
        let (st, e, msg) = estimate_of(scene, path, res, settings);
        assert_eq!(st, want, "{what}: {msg}");
        assert!(!msg.is_empty(), "{what}: a message");
        assert_eq!((e.dense_bytes, e.in_memory_bytes), (0, 0), "{what}: out zeroed");
    }
    let _ = std::fs::remove_file(&junk);
    let mut out = VsLpmEstimate::default();
    let c = CString::new(p).unwrap();
    unsafe {
        assert_eq!(vs_scene_lpm_estimate(scene, std::ptr::null(), std::ptr::null(), std::ptr::null(), 0, std::ptr::null(), &mut out), VsStatus::NullArgument);
        assert_eq!(vs_scene_lpm_estimate(scene, c.as_ptr(), std::ptr::null(), std::ptr::null(), 0, std::ptr::null(), std::ptr::null_mut()), VsStatus::NullArgument);
        assert_eq!(vs_scene_lpm_estimate(std::ptr::null_mut(), c.as_ptr(), std::ptr::null(), std::ptr::null(), 0, std::ptr::null(), &mut out), VsStatus::NullArgument);
        assert_eq!(vs_scene_destroy(scene), VsStatus::Ok);
    }
}
