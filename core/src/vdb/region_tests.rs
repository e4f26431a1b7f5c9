//! `load_float_grid_region`: a slab of z read from every fixture file (OpenVDB's and Blender's:
//! Blosc, Zip, half, tiles) and from our writer's files equals the whole grid inside the slab,
//! and the leaves outside it are stepped over, not decoded.

use std::path::{Path, PathBuf};

use glam::IVec3;

use super::*;
use crate::medium::GridLimits;

/// The shared fixtures' VDB files (none when shared/fixtures is not beside the repository).
pub(super) fn files() -> Vec<PathBuf> {
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures");
    let mut v: Vec<PathBuf> = std::fs::read_dir(f.join("vdb")).map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|e| e == "vdb")).collect()).unwrap_or_default();
    v.push(f.join("blender_noise_cube/volumes/Volume.vdb"));
    v.retain(|p| p.is_file());
    v.sort();
    v
}

fn check(path: &Path) -> Option<usize> {
    let file = VdbFile::open(path, u64::MAX).unwrap();
    let i = file.find_density_grid(None).ok()?;
    let Ok((whole, _)) = file.load_float_grid(i, GridLimits::default()) else { return None };
    if whole.is_empty() {
        return None;
    }
    let (lo, hi) = whole.bbox();
    // A slab of 8 z-planes through the middle, leaf-aligned, whole in x and y.
    let z0 = ((lo.z + hi.z) / 2).div_euclid(8) * 8;
    let region = (IVec3::new(lo.x, lo.y, z0), IVec3::new(hi.x + 1, hi.y + 1, z0 + 8));
    let (part, _, skipped) = file.load_float_grid_region(i, GridLimits::default(), Some(region)).unwrap();
    for z in z0..z0 + 8 {
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                let c = IVec3::new(x, y, z);
                assert_eq!(part.voxel(c), whole.voxel(c), "{} at {c}", path.display());
            }
        }
    }
    assert!(part.memory_bytes() <= whole.memory_bytes(), "{}", path.display());
    Some(skipped)
}

#[test]
fn region_read_equals_the_whole_grid_inside_and_skips_the_leaves_outside() {
    let dir = std::env::temp_dir().join(format!("volscatter-region-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (plume, xf) = crate::medium::procedural::plume(48, GridLimits::default()).unwrap();
    let mut ours = Vec::new();
    for (k, (half, compression)) in [(false, VdbCompression::None), (false, VdbCompression::Zip), (true, VdbCompression::Zip)].into_iter().enumerate() {
        let p = dir.join(format!("plume{k}.vdb"));
        write_float_grid(&p, "density", &plume, xf, &WriteOptions { half, compression, ..Default::default() }).unwrap();
        ours.push(p);
    }
    for p in &ours {
        let skipped = check(p).unwrap();
        eprintln!("{}: {skipped} leaves skipped", p.display());
        assert!(skipped > 0, "{}", p.display());
    }
    let fixtures = files();
    if fixtures.is_empty() {
        eprintln!("SKIPPED the fixture files: shared/fixtures not found beside the repository");
    }
    for p in fixtures {
        let r = check(&p);
        eprintln!("{}: {r:?} leaves skipped", p.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
