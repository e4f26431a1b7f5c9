//! Tests of `write_grids` (mixed_writer.rs): float, vec3s and copied grids in one file, read
//! back by this module's reader; copies refused; nothing left behind on failure.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3, IVec3};

use super::bytes::bit;
use super::tree::Visitor;
use super::values::ValueKind;
use super::*;

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volscatter-mixed-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn names_in(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// Every active voxel of a grid, by index: its values.
#[derive(Default)]
struct Voxels(BTreeMap<(i32, i32, i32), Vec<f64>>, usize);

impl Visitor for Voxels {
    fn tile(&mut self, origin: IVec3, log2: u32, _value: &[f64], active: bool) -> Result<()> {
        assert!(!active, "no active tiles expected at {origin} (log2 {log2})");
        Ok(())
    }
    fn leaf(&mut self, origin: IVec3, mask: &[u64; 8], values: &[f64]) -> Result<()> {
        let k = self.1;
        for i in (0..512).filter(|&i| bit(mask, i)) {
            let p = origin + IVec3::new((i >> 6) as i32, ((i >> 3) & 7) as i32, (i & 7) as i32);
            self.0.insert((p.x, p.y, p.z), values[i * k..(i + 1) * k].to_vec());
        }
        Ok(())
    }
}

fn voxels(f: &VdbFile, i: usize) -> BTreeMap<(i32, i32, i32), Vec<f64>> {
    let kind = ValueKind::from_tree_type(&f.grids[i].grid_type).unwrap();
    let mut v = Voxels(BTreeMap::new(), kind.comps);
    f.visit_tree(i, kind, &mut v).unwrap();
    v.0
}

/// An index-to-world map that single precision does not hold exactly.
fn map() -> DMat4 {
    DMat4::from_cols_array(&[0.05, 0.0, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 1.0, -2.0, 0.5, 1.0])
}

/// A dense array of `dims` x `k` floats, about a third of the voxels 0.
fn dense(dims: [u32; 3], k: usize, seed: u64) -> Vec<f32> {
    let n = (dims[0] * dims[1] * dims[2]) as usize;
    let mut s = seed;
    (0..n * k)
        .map(|i| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            if (i / k) % 3 == 0 { 0.0 } else { (s >> 40) as f32 / 1024.0 }
        })
        .collect()
}

#[test]
fn float_vec3s_and_copied_grids_round_trip() {
    let d = dir("rt");
    // The source of the copy: a float grid with its own map, written by the float writer.
    let src = d.join("density.vdb");
    let ddims = [5u32, 6, 7];
    let dens = dense(ddims, 1, 1);
    let src_xf = glam::Affine3A::from_scale(glam::Vec3::splat(0.2));
    write_dense_float_grids(&src, &[DenseFloat { name: "density", dims: ddims, values: &dens }], src_xf, &WriteOptions::default()).unwrap();

    // 140 x 130 crosses an Internal4 border at 128.
    let dims = [9u32, 140, 130];
    let rgb = dense(dims, 3, 2);
    let red: Vec<f32> = rgb.chunks(3).map(|c| c[0]).collect();
    let out = d.join("all.vdb");
    let grids = [
        GridSource::Copy(GridCopy { name: "dens", source: &src, grid: "density" }),
        GridSource::Vec3s(DenseVec3s { name: "scatter", dims, values: &rgb }),
        GridSource::Float(DenseFloat { name: "scatter_r", dims, values: &red }),
    ];
    write_grids(&out, &grids, map(), &WriteOptions::default()).unwrap();
    assert_eq!(names_in(&d), ["all.vdb", "density.vdb"], "no temporary left");

    let f = VdbFile::open(&out, 1 << 30).unwrap();
    assert_eq!(f.header.version, header::WRITE_FILE_VERSION);
    let listed: Vec<(&str, &str)> = f.grids.iter().map(|g| (g.name.as_str(), g.grid_type.as_str())).collect();
    assert_eq!(listed, [("dens", "Tree_float_5_4_3"), ("scatter", "Tree_vec3s_5_4_3"), ("scatter_r", "Tree_float_5_4_3")]);

    // vec3s: every voxel back, active where any component is not 0; map in double precision.
    let v = voxels(&f, 1);
    let (nx, ny) = (dims[0] as usize, dims[1] as usize);
    let mut active = 0;
    for (i, c) in rgb.chunks(3).enumerate() {
        let p = ((i % nx) as i32, ((i / nx) % ny) as i32, (i / (nx * ny)) as i32);
        match v.get(&p) {
            Some(got) => {
                active += 1;
                assert_eq!(got, &c.iter().map(|x| *x as f64).collect::<Vec<_>>(), "{p:?}");
            }
            None => assert!(c.iter().all(|x| *x == 0.0), "{p:?} lost"),
        }
    }
    assert_eq!(v.len(), active);
    let info = f.grid_info(1).unwrap();
    assert_eq!((info.transform.as_str(), info.compression.as_str(), info.class.as_str()), ("AffineMap", "none + active mask", "unknown"));
    assert_eq!(info.active_voxels, Some(active as u64));
    let head = f.grid_head(1).unwrap();
    let w = head.transform.index_to_world.transform_point3(DVec3::new(3.0, 4.0, 5.0));
    assert!((w - map().transform_point3(DVec3::new(3.0, 4.0, 5.0))).abs().max_element() < 1e-12, "{w}");

    // float: the values and the map in single precision (Zip, as the float writer).
    let (g, xf) = f.load_float_grid(2, GridLimits::default()).unwrap();
    for (i, r) in red.iter().enumerate() {
        assert_eq!(g.voxel(IVec3::new((i % nx) as i32, ((i / nx) % ny) as i32, (i / (nx * ny)) as i32)), *r);
    }
    assert!(xf.abs_diff_eq(glam::Affine3A::from_mat4(map().as_mat4()), 1e-7));
    assert!(f.grid_info(2).unwrap().compression.contains("zip"));

    // The copy: the source grid's bytes unchanged, its own map and values.
    let s = VdbFile::open(&src, 1 << 30).unwrap();
    let bytes = |path: &Path, g: &header::GridDescriptor| std::fs::read(path).unwrap()[g.grid_pos as usize..g.end_pos as usize].to_vec();
    assert_eq!(bytes(&out, &f.grids[0]), bytes(&src, &s.grids[0]));
    let (c, cxf) = f.load_float_grid(0, GridLimits::default()).unwrap();
    assert!(cxf.abs_diff_eq(src_xf, 1e-7));
    assert_eq!(c.sum_and_count_nonzero(), s.load_float_grid(0, GridLimits::default()).unwrap().0.sum_and_count_nonzero());

    // Rewriting the same path replaces it whole.
    write_grids(&out, &grids[1..2], map(), &WriteOptions::default()).unwrap();
    assert_eq!(VdbFile::open(&out, 1 << 30).unwrap().grids.len(), 1);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn copies_refused_and_nothing_left_behind() {
    let d = dir("refuse");
    let src = d.join("src.vdb");
    let ones = [1.0f32; 8];
    write_dense_float_grids(&src, &[DenseFloat { name: "density", dims: [2, 2, 2], values: &ones }], glam::Affine3A::IDENTITY, &WriteOptions::default()).unwrap();
    let out = d.join("out.vdb");
    let one = |c: GridCopy<'_>| write_grids(&out, &[GridSource::Float(DenseFloat { name: "a", dims: [2, 2, 2], values: &ones }), GridSource::Copy(c)], DMat4::IDENTITY, &WriteOptions::default());

    // A grid the file lacks.
    let e = one(GridCopy { name: "d", source: &src, grid: "nope" }).unwrap_err();
    assert!(matches!(e, Error::Format { .. }) && e.to_string().contains("nope"), "{e}");
    // A file version the copy does not take verbatim.
    let mut old = std::fs::read(&src).unwrap();
    old[8..12].copy_from_slice(&223u32.to_le_bytes());
    let old_path = d.join("old.vdb");
    std::fs::write(&old_path, &old).unwrap();
    let e = one(GridCopy { name: "d", source: &old_path, grid: "density" }).unwrap_err();
    assert!(matches!(e, Error::Unsupported { .. }) && e.to_string().contains("223"), "{e}");
    // A missing source.
    let e = one(GridCopy { name: "d", source: &d.join("missing.vdb"), grid: "density" }).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
    // A bad name, bad values, no grids.
    assert!(matches!(one(GridCopy { name: "a\u{1e}b", source: &src, grid: "density" }), Err(Error::InvalidArgument(_))));
    let nan = [f32::NAN; 24];
    let vec3 = |values: &[f32]| write_grids(&out, &[GridSource::Vec3s(DenseVec3s { name: "v", dims: [2, 2, 2], values })], DMat4::IDENTITY, &WriteOptions::default());
    assert!(matches!(vec3(&nan), Err(Error::InvalidArgument(_))));
    assert!(matches!(vec3(&nan[..23]), Err(Error::InvalidArgument(_))));
    assert!(matches!(write_grids(&out, &[], DMat4::IDENTITY, &WriteOptions::default()), Err(Error::InvalidArgument(_))));
    assert_eq!(names_in(&d), ["old.vdb", "src.vdb"], "nothing written by a refused call");

    // A failing write leaves the old file as it was and no temporary.
    std::fs::write(&out, b"before").unwrap();
    assert!(one(GridCopy { name: "d", source: &d.join("missing.vdb"), grid: "density" }).is_err());
    assert_eq!(std::fs::read(&out).unwrap(), b"before");
    // A rename that fails (the path is a non-empty folder) after the temporary was written.
    let folder = d.join("folder.vdb");
    std::fs::create_dir_all(folder.join("x")).unwrap();
    let e = write_grids(&folder, &[GridSource::Copy(GridCopy { name: "d", source: &src, grid: "density" })], DMat4::IDENTITY, &WriteOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && e.to_string().contains("folder.vdb"), "{e}");
    assert_eq!(names_in(&d), ["folder.vdb", "old.vdb", "out.vdb", "src.vdb"], "no temporary left");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The same grids give the same bytes wherever and whenever they are written (a farm's re-run
/// frame equals the first: the UUID comes from the content), and other values another UUID.
#[test]
fn same_grids_same_bytes_other_grids_other_uuid() {
    let d = dir("uuid");
    let dims = [5, 4, 3];
    let (a, b) = (dense(dims, 3, 1), dense(dims, 3, 2));
    let write = |name: &str, values: &[f32]| {
        let p = d.join(name);
        write_grids(&p, &[GridSource::Vec3s(DenseVec3s { name: "scatter", dims, values })], map(), &WriteOptions::default()).unwrap();
        std::fs::read(p).unwrap()
    };
    let (first, again, other) = (write("a.vdb", &a), write("a_again.vdb", &a), write("b.vdb", &b));
    assert_eq!(first, again, "the same grids written twice differ");
    let uuid = |f: &[u8]| f[21..57].to_vec();
    assert_ne!(uuid(&first), uuid(&other), "other grids kept the same UUID");
    assert!(VdbFile::open(&d.join("a.vdb"), u64::MAX).is_ok(), "a stamped file must still read");
    std::fs::remove_dir_all(&d).unwrap();
}
