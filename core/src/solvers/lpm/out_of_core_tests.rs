//! The out-of-core solve against the in-memory one (equal to the bit), its memory (a slab,
//! growing with the map, not the volume), its refusals, and its scratch files (gone after a
//! success, an error and a cancel).

use crate::solvers::SolveCtx;
use crate::solvers::SolveOutput;
use crate::solvers::Solver;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;

use super::out_of_core::{plan, slab_bytes};
use super::{FirstOrder, Lpm, LpmReport, LpmSettings, Overrides};
use crate::medium::{Emission, EmissionLaw, EmissionTerm};
use crate::scene::{Light, Scene};
use crate::solvers::testing::fixture_scene as case;
use crate::stages::{NoProgress, Progress, ScatteringGrid};

/// A fresh scratch directory of its own per test, so that "no file left" is checkable while
/// other tests run.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("volscatter-ooc-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn files_in(d: &PathBuf) -> usize {
    std::fs::read_dir(d).unwrap().count()
}

fn solve(sc: &Scene, s: LpmSettings, ov: Overrides, dir: Option<&PathBuf>, progress: &dyn Progress) -> crate::error::Result<(ScatteringGrid, LpmReport)> {
    let mut lpm = Lpm::new(s)?;
    if let Some(d) = dir {
        lpm = lpm.with_scratch_dir(d);
    }
    lpm.with_overrides(ov).solve(sc, &mut SolveCtx::new(progress)).map(SolveOutput::split::<LpmReport>).map(|(o, r)| (o.scattering, r))
}

fn worst_relative(a: &[Vec3], b: &[Vec3]) -> f32 {
    let top = b.iter().fold(0.0f32, |m, v| m.max(v.max_element()));
    assert!(top > 0.0);
    a.iter().zip(b).map(|(x, y)| (*x - *y).abs().max_element()).fold(0.0f32, f32::max) / top
}

/// The plume (a sun, `first_order: boundary`, which streams) out of core with slabs of 4, 8,
/// 16 layers and the whole volume against in memory: J (orders two and up) and S (single
/// scattering plus the upsampled J) within 1e-6 relative (the same sums in the same order:
/// measured equal to the bit). The scratch files are gone afterwards.
#[test]
fn lpm_out_of_core_equals_in_memory() {
    let sc = case("plume");
    let dir = scratch("equal");
    let s = LpmSettings { grid_resolution: 24, directions: 9, max_orders: 3, output_resolution: 32, first_order: FirstOrder::Boundary, ..Default::default() };
    let ooc = LpmSettings { out_of_core: true, ..s.clone() };
    let j_only = |layers| Overrides { layers, j_only: true, ..Default::default() };
    let (_, mem) = solve(&sc, s.clone(), j_only(None), None, &NoProgress).unwrap();
    let jm = &mem.j.as_ref().unwrap().data;
    for layers in [Some(4usize), Some(8), Some(16), None] {
        let (_, rep) = solve(&sc, ooc.clone(), j_only(layers), Some(&dir), &NoProgress).unwrap();
        let worst = worst_relative(&rep.j.as_ref().unwrap().data, jm);
        eprintln!("out of core, slabs of {layers:?}: worst |J - J in memory| / max {worst:e}, {} slabs, max U per order {:?} vs {:?}", rep.sweep.slabs, rep.max_u, mem.max_u);
        assert!(worst <= 1e-6, "{layers:?}: {worst}");
        assert_eq!(rep.max_u, mem.max_u, "{layers:?}");
        assert_eq!(rep.orders, mem.orders);
        assert_eq!(files_in(&dir), 0, "scratch files left after a solve");
    }
    let (s_mem, _) = solve(&sc, s, Overrides::default(), None, &NoProgress).unwrap();
    // S also streamed to a VDB, 8 planes at a time: it reads back as the returned grid.
    let vdb_dir = scratch("equal-vdb");
    let vdb = vdb_dir.join("S.vdb");
    let lpm = Lpm::new(ooc).unwrap().with_scratch_dir(&dir).with_s_vdb(&vdb);
    let s_ooc = lpm.with_overrides(Overrides { layers: Some(5), ..Default::default() }).solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<LpmReport>).unwrap().0.scattering;
    let worst = worst_relative(&s_ooc.data, &s_mem.data);
    eprintln!("out of core S vs in memory: worst relative {worst:e}");
    assert!(worst <= 1e-6, "S: {worst}");
    assert_eq!(files_in(&dir), 0);
    let file = crate::vdb::VdbFile::open(&vdb, u64::MAX).unwrap();
    let [nx, ny, nz] = s_ooc.dims.map(|d| d as i32);
    for (c, ch) in ["r", "g", "b"].iter().enumerate() {
        let i = file.find_density_grid(Some(&format!("scattering_{ch}"))).unwrap();
        let (g, xf) = file.load_float_grid(i, Default::default()).unwrap();
        assert!(xf.abs_diff_eq(s_ooc.index_to_world, 1e-6), "{xf:?}");
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let v = s_ooc.data[(x + nx * (y + ny * z)) as usize][c];
                    assert_eq!(g.voxel(glam::IVec3::new(x, y, z)), v, "{ch} at {x} {y} {z}");
                }
            }
        }
    }
    assert_eq!(files_in(&vdb_dir), 1, "the VDB alone, no scratch left beside it");
    let _ = std::fs::remove_dir_all(&vdb_dir);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Emission (the first propagation's U, written while the grid is built) and a dome: equal
/// to in memory as well.
#[test]
fn lpm_out_of_core_equals_in_memory_with_emission_and_dome() {
    let mut sc = case("dome_uniform");
    let m = &sc.medium;
    let term = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Linear { color: Vec3::new(3.0, 2.0, 1.0) });
    sc.medium.emission = Some(Emission { terms: vec![term], vpl_count: 16 });
    let dir = scratch("emission");
    let s = LpmSettings { grid_resolution: 16, directions: 9, max_orders: 3, output_resolution: 24, first_order: FirstOrder::Boundary, ..Default::default() };
    let (a, ra) = solve(&sc, s.clone(), Overrides::default(), None, &NoProgress).unwrap();
    let (b, rb) = solve(&sc, LpmSettings { out_of_core: true, ..s }, Overrides { layers: Some(3), ..Default::default() }, Some(&dir), &NoProgress).unwrap();
    assert_eq!(ra.max_u, rb.max_u);
    let worst = worst_relative(&b.data, &a.data);
    assert!(worst <= 1e-6, "{worst}");
    assert_eq!(files_in(&dir), 0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Memory out of core, counted from every buffer the sweeps hold (maps, T, and the boxes of
/// sigma_t, U in, U out and J: the whole solve's per-cell arrays, not only the propagation's):
/// within `slab_bytes` (the formula) plus O(n^2) (capacity rounding of map-sized buffers), and
/// at the same slab a 32^3 grid costs 4x a 16^3 one, not 8x. The plan refuses a budget below
/// one layer with the size needed, and picks the most layers that fit.
#[test]
fn lpm_out_of_core_memory_is_a_slab() {
    let dirs = super::directions::Directions::new(5, 1);
    let one = slab_bytes(128 * 128, 25, 1, 6, 1);
    let err = plan([128; 3], &dirs, 6, one - 1).unwrap_err().to_string();
    assert!(err.contains("memory_budget") && err.contains("out of core"), "{err}");
    assert_eq!(plan([128; 3], &dirs, 6, slab_bytes(128 * 128, 25, 1, 6, 8)).unwrap(), [8; 6]);
    assert_eq!(plan([128; 3], &dirs, 6, slab_bytes(128 * 128, 25, 1, 6, 9) - 1).unwrap(), [8; 6]);
    assert_eq!(slab_bytes(256 * 256, 25, 1, 6, 16) / slab_bytes(128 * 128, 25, 1, 6, 16), 4);
    let sc = case("dome_uniform");
    let dir = scratch("memory");
    let peak = |res: u32| {
        let s = LpmSettings { grid_resolution: res, directions: 9, max_orders: 1, out_of_core: true, first_order: FirstOrder::Boundary, ..Default::default() };
        let (_, rep) = solve(&sc, s, Overrides { layers: Some(4), j_only: true, ..Default::default() }, Some(&dir), &NoProgress).unwrap();
        let n = rep.grid_dims.iter().copied().max().unwrap();
        assert_eq!(rep.grid_dims, [n; 3], "a cube's grid");
        (n, rep.sweep.peak_working_bytes, rep.cell_bytes)
    };
    let (n16, p16, disk16) = peak(16);
    let (n32, p32, disk32) = peak(32);
    eprintln!("out of core, slabs of 4: {n16}^3 {p16} B ({disk16} B on disk), {n32}^3 {p32} B ({disk32} B on disk): x{:.2} in memory, x{:.2} on disk", p32 as f64 / p16 as f64, disk32 as f64 / disk16 as f64);
    for (n, p) in [(n16, p16), (n32, p32)] {
        let formula = slab_bytes(n * n, 9, 1, 6, 4);
        assert!(p >= formula && p <= formula + 64 * (n * n) as u64, "{n}: {p} vs formula {formula}");
    }
    // A little under 4x: the gathered run of layers is at most `RUN_BYTES` of T (4 layers of
    // the 16^3 grid's map, 2 of the 32^3's).
    let grows = p32 as f64 / p16 as f64;
    assert!(grows > 3.5 && grows < 4.05, "{p16} {p32}");
    assert!((disk32 as f64 / disk16 as f64 - 8.0).abs() < 0.05, "the arrays themselves grow with the volume, on disk");
    let _ = std::fs::remove_dir_all(&dir);
}

/// What needs the whole grid at once is refused with a message naming the setting: a local
/// light, and a sun with the exact first order. A scratch directory that does not exist is an
/// error, not a panic.
#[test]
fn lpm_out_of_core_refusals() {
    let s = LpmSettings { grid_resolution: 8, directions: 1, max_orders: 1, out_of_core: true, ..Default::default() };
    let sun = case("plume");
    let err = solve(&sun, s.clone(), Overrides::default(), None, &NoProgress).err().unwrap().to_string();
    assert!(err.contains("first_order") && err.contains("out_of_core"), "{err}");
    let mut lamp = case("plume");
    lamp.lights = vec![Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE, radius: 0.0, interior: Default::default() }];
    let err = solve(&lamp, LpmSettings { first_order: FirstOrder::Boundary, ..s.clone() }, Overrides::default(), None, &NoProgress).err().unwrap().to_string();
    assert!(err.contains("local light"), "{err}");
    let missing = PathBuf::from("/nonexistent/volscatter-scratch");
    let err = solve(&case("dome_uniform"), LpmSettings { first_order: FirstOrder::Boundary, ..s }, Overrides::default(), Some(&missing), &NoProgress).err().unwrap().to_string();
    assert!(err.contains("volscatter-lpm"), "{err}");
}

/// Cancels once the flag has been read `after` times.
struct CancelAfter {
    reads: AtomicUsize,
    after: usize,
}

impl Progress for CancelAfter {
    fn update(&self, _: &str, _: f32) -> bool {
        !self.cancelled()
    }
    fn cancelled(&self) -> bool {
        self.reads.fetch_add(1, Ordering::Relaxed) >= self.after
    }
}

/// A cancel at any point (while the grid is built, in a sweep, in the output) returns
/// `Cancelled` and leaves no scratch file.
#[test]
fn lpm_out_of_core_cancel_removes_the_scratch_files() {
    let sc = case("plume");
    let dir = scratch("cancel");
    let s = LpmSettings { grid_resolution: 16, directions: 9, max_orders: 3, output_resolution: 16, out_of_core: true, first_order: FirstOrder::Boundary, ..Default::default() };
    // How many times a whole solve reads the flag, then cancels spread over that.
    let count = CancelAfter { reads: AtomicUsize::new(0), after: usize::MAX };
    solve(&sc, s.clone(), Overrides { layers: Some(4), ..Default::default() }, Some(&dir), &count).unwrap();
    let total = count.reads.load(Ordering::Relaxed);
    for after in [0usize, 5, total / 10, total / 2, total * 9 / 10, total - 2] {
        let p = CancelAfter { reads: AtomicUsize::new(0), after };
        let r = solve(&sc, s.clone(), Overrides { layers: Some(4), ..Default::default() }, Some(&dir), &p);
        assert!(matches!(r, Err(crate::error::Error::Cancelled)), "cancel after {after} reads: {:?}", r.map(|_| ()));
        assert_eq!(files_in(&dir), 0, "cancel after {after}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 19's "volume larger than RAM": the medium read from a VDB box-filtered as it is read
/// (`medium.max_resolution`, vdb/filter.rs). The plume written to a VDB and loaded through the
/// scene's option gives the grid the same filter gives over the file in memory, to the bit,
/// and so the same out-of-core S. Against the full-resolution medium (the plume at 64^3, grid
/// 16): the difference the filter makes to the composited image (each with its own medium's
/// transmittance and single scattering), at max_resolution 32 (2x the grid) and 16 (the
/// grid's); see the bound's comment.
#[test]
fn lpm_out_of_core_on_a_box_filtered_vdb_medium() {
    let mut sc = case("plume");
    let (grid, xf) = crate::medium::procedural::plume(64, Default::default()).unwrap();
    sc.medium = crate::medium::Medium::new(grid, xf, sc.medium.density_scale, sc.medium.albedo, sc.medium.g);
    let dir = scratch("filtered");
    let vdb = dir.join("plume.vdb");
    let m = &sc.medium;
    let opts = crate::vdb::WriteOptions { compression: crate::vdb::VdbCompression::Zip, ..Default::default() };
    crate::vdb::write_float_grid(&vdb, "density", &m.grid, m.index_to_world, &opts).unwrap();
    let s = LpmSettings { grid_resolution: 16, directions: 9, max_orders: 3, output_resolution: 32, first_order: FirstOrder::Boundary, out_of_core: true, ..Default::default() };
    let (full, _) = solve(&sc, s.clone(), Overrides::default(), Some(&dir), &NoProgress).unwrap();
    let mut differences = Vec::new();
    for max_resolution in [32u32, 16] {
        let json = format!(
            r#"{{"format": 1, "medium": {{"vdb": "plume.vdb", "max_resolution": {max_resolution}, "density_scale": {:?}, "albedo": {:?}, "g": {}}},
                "camera": {{"position": [0, -4, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 40, "width": 8, "height": 8}}}}"#,
            m.density_scale.to_array(),
            m.albedo.to_array(),
            m.g
        );
        let streamed = Scene::from_json_str(&json, &dir).unwrap().medium;
        let file = crate::vdb::VdbFile::from_bytes(std::fs::read(&vdb).unwrap(), &vdb).unwrap();
        let (grid, xf, report) = file.load_float_grid_filtered(0, crate::vdb::MaxResolution::new(max_resolution).unwrap(), Default::default()).unwrap();
        assert_eq!(streamed.index_to_world, xf);
        let (lo, hi) = grid.bbox();
        assert_eq!(streamed.grid.bbox(), (lo, hi));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let c = glam::IVec3::new(x, y, z);
                    assert_eq!(streamed.grid.voxel(c).to_bits(), grid.voxel(c).to_bits(), "{c}");
                }
            }
        }
        let mut a = sc.clone();
        a.medium = streamed;
        let mut b = sc.clone();
        b.medium.grid = grid;
        b.medium.index_to_world = xf;
        b.medium.world_to_index = xf.inverse();
        let (sa, _) = solve(&a, s.clone(), Overrides::default(), Some(&dir), &NoProgress).unwrap();
        let (sb, _) = solve(&b, s.clone(), Overrides::default(), Some(&dir), &NoProgress).unwrap();
        assert_eq!(sa.data, sb.data, "max_resolution {max_resolution}");
        let image = |sc: &Scene, s: &ScatteringGrid| crate::solvers::testing::rgb(&crate::compositor::composite(sc, s, &Default::default()).unwrap());
        let diff = crate::image::relative_rmse(&image(&a, &sa), &image(&sc, &full));
        eprintln!("max_resolution {max_resolution} (factor {}, {:?} cells): image against the full-resolution medium's, rel. RMSE {diff:.4}", report.factor, report.coarse_dims);
        differences.push(diff);
    }
    assert_eq!(files_in(&dir), 1, "the VDB alone, no scratch left");
    let _ = std::fs::remove_dir_all(&dir);
    // Measured 0.0165 (2x the grid) and 0.0408 (the grid's resolution); bounds = measured +
    // 10% + 0.002, as the ratchets. A medium filtered to twice the grid's cells changes the
    // answer by under 2%: the grid's cells average 4^3 voxels either way, what differs is the
    // mip's finer levels (the upsampling guide) and the compositor's transmittance.
    assert!(differences[0] <= 0.0202 && differences[1] <= 0.047, "{differences:?}");
    assert!(differences[0] < differences[1], "{differences:?}");
}

/// The estimate hosts show before a solve (estimate.rs, `vs_scene_lpm_estimate`) against the
/// solves themselves, from the medium's world box alone: the same grid, the out-of-core
/// scratch files to the byte, and the sweeps' measured peak within the formula plus O(n^2)
/// (capacity rounding of map-sized buffers, as `lpm_out_of_core_memory_is_a_slab` allows), in
/// memory and out of core under a budget of a few layers; a budget below one layer gives 0
/// where the solve refuses.
#[test]
fn lpm_estimate_matches_the_solves_plan() {
    let sc = case("dome_uniform");
    let (lo, hi) = sc.medium.world_bounds();
    let dir = scratch("estimate");
    let base = LpmSettings { grid_resolution: 16, directions: 9, max_orders: 1, first_order: FirstOrder::Boundary, ..Default::default() };
    let n2 = 16 * 16;
    let budget = slab_bytes(n2, 9, 1, 6, 5) + 100;
    for (out_of_core, memory_budget) in [(false, 0), (false, super::stream::working_bytes(n2, 9, 1, 3)), (true, budget), (true, 0)] {
        let s = LpmSettings { out_of_core, memory_budget, ..base.clone() };
        let est = super::estimate::memory(lo, hi, &s).unwrap();
        let (_, rep) = solve(&sc, s.clone(), Overrides { j_only: true, ..Default::default() }, Some(&dir), &NoProgress).unwrap();
        assert_eq!(est.grid_dims, rep.grid_dims, "{s:?}");
        let peak = rep.sweep.peak_working_bytes;
        let (formula, what) = if out_of_core {
            assert_eq!(est.scratch_bytes, rep.cell_bytes, "scratch files");
            (est.out_of_core_bytes, "out of core")
        } else {
            (est.in_memory_bytes - rep.cell_bytes, "in memory (sweeps)")
        };
        eprintln!("{what}, budget {memory_budget}: estimate {formula} B, measured peak {peak} B, layers {:?}", rep.layers);
        assert!(peak >= formula && peak <= formula + 64 * n2 as u64, "{what}: peak {peak} vs estimate {formula}");
        assert!(memory_budget == 0 || formula <= memory_budget, "{what}: {formula} over the budget {memory_budget}");
    }
    let tiny = LpmSettings { out_of_core: true, memory_budget: slab_bytes(n2, 9, 1, 6, 1) - 1, ..base.clone() };
    assert_eq!(super::estimate::memory(lo, hi, &tiny).unwrap().out_of_core_bytes, 0);
    assert!(solve(&sc, tiny, Overrides::default(), Some(&dir), &NoProgress).is_err());
    assert!(super::estimate::memory(lo, hi, &LpmSettings { directions: 7, ..base }).is_err(), "invalid settings are refused");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Counts the scratch files that have a name in `dir` each time the cancel flag is read.
#[cfg(unix)]
struct WatchDir<'a> {
    dir: &'a PathBuf,
    most: AtomicUsize,
}

#[cfg(unix)]
impl Progress for WatchDir<'_> {
    fn update(&self, _: &str, _: f32) -> bool {
        !self.cancelled()
    }
    fn cancelled(&self) -> bool {
        self.most.fetch_max(files_in(self.dir), Ordering::Relaxed);
        false
    }
}

/// While an out-of-core solve runs, its scratch files have no name (unlinked once open), so
/// nothing is left behind when the process dies mid-solve (SIGKILL, the OOM killer, a crash),
/// where no drop runs. Looked at every time the solve reads its cancel flag.
#[cfg(unix)]
#[test]
fn harden_lpm_out_of_core_scratch_files_are_nameless_while_solving() {
    let sc = case("plume");
    let dir = scratch("nameless");
    let s = LpmSettings { grid_resolution: 16, directions: 9, max_orders: 3, output_resolution: 16, out_of_core: true, first_order: FirstOrder::Boundary, ..Default::default() };
    let watch = WatchDir { dir: &dir, most: AtomicUsize::new(0) };
    solve(&sc, s, Overrides { layers: Some(4), ..Default::default() }, Some(&dir), &watch).unwrap();
    assert_eq!(watch.most.load(Ordering::Relaxed), 0, "scratch files with a name in {} during the solve", dir.display());
    let _ = std::fs::remove_dir_all(&dir);
}
