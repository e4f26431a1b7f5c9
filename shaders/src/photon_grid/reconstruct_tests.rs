use super::reconstruct::{ReconstructParams, WGSL};
use super::*;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use volscatter_core::solvers::testing::fixture_scene;
use std::sync::{Arc, Mutex};
use volscatter_core::image::relative_rmse;
use volscatter_core::solvers::photon_grid::backend::CpuBackend;
use volscatter_core::solvers::photon_grid::{PhotonGrid, SingleScattering, Upsampling};
use volscatter_core::stages::NoProgress;

#[test]
fn wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(WGSL, "Params") as usize, size_of::<ReconstructParams>());
}

/// Traces on the CPU (deterministic: the same tallies every run) and reconstructs each frame
/// on both the CPU and the GPU, keeping both grids; the solve goes on with the CPU's.
struct Both {
    gpu: GpuPhotonBackend,
    /// Shared with the test, which keeps it while the solve owns the backend.
    grids: Arc<Mutex<Vec<(ScatteringGrid, ScatteringGrid)>>>,
}

impl PhotonBackend for Both {
    fn trace_generations(&self, job: &TraceJob, generations: &[u64]) -> Result<Vec<Generation>> {
        CpuBackend.trace_generations(job, generations)
    }
    fn reconstruct(&self, medium: &Medium, tallies: &[Tallies], camera: Vec3, settings: &PhotonGridSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
        let cpu = CpuBackend.reconstruct(medium, tallies, camera, settings, progress)?;
        let gpu = self.gpu.reconstruct(medium, tallies, camera, settings, progress)?;
        self.grids.lock().unwrap().push((cpu.clone(), gpu));
        Ok(cpu)
    }
}

/// Small enough for lavapipe; every order from photons so that S is the reconstruction's alone.
fn settings(upsampling: Upsampling) -> PhotonGridSettings {
    PhotonGridSettings {
        photons: 1 << 15,
        cache_resolution: 12,
        output_resolution: 32,
        single_scattering: SingleScattering::Photons,
        upsampling,
        ..Default::default()
    }
}

/// The CPU's and the GPU's reconstruction of the same tallies (one CPU trace).
fn both(ctx: &Arc<GpuContext>, scene: &Scene, s: &PhotonGridSettings) -> (ScatteringGrid, ScatteringGrid) {
    let grids = Arc::new(Mutex::new(Vec::new()));
    let backend: Box<dyn PhotonBackend> = Box::new(Both { gpu: GpuPhotonBackend::new(ctx), grids: grids.clone() });
    crate::test_support::solve_on(&PhotonGrid::new(s.clone()).unwrap(), scene, &NoProgress, &backend, None).unwrap();
    let pair = grids.lock().unwrap().pop().unwrap();
    pair
}

/// The largest difference of two grids' values over the largest value of `b` (per channel).
fn max_rel(a: &[Vec3], b: &[Vec3]) -> f32 {
    let scale = b.iter().fold(0.0f32, |m, v| m.max(v.max_element()));
    a.iter().zip(b).fold(0.0f32, |m, (x, y)| m.max((*x - *y).abs().max_element())) / scale.max(1e-30)
}

/// reconstruct.wgsl against reconstruct.rs on the same tallies: the plume under its sun and
/// beside a point light (shared fixtures), both upsamplings. Same cells, weights and order of
/// summation; the GPU may fuse multiply-adds, evaluates the affine maps as dot products, and its
/// exp / pow / sqrt round differently (WGSL allows a few ulp; the physical filter's f_exp is
/// f64 on the CPU, f32 here), so S differs in float rounding only. Measured on lavapipe
/// (relative RMSE / largest difference over the largest S): plume trilinear 9.0e-8 / 2.7e-7,
/// physical 3.8e-7 / 6.4e-7; plume_point trilinear 2.5e-8 / 1.2e-7, physical 1.6e-7 / 3.6e-7.
/// Bound 1e-5 on both: a few tens of f32 operations per lobe, each within a few ulp (1e-7),
/// with room for a real GPU's transcendental functions (which may be less exact than lavapipe's).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_reconstruction_matches_cpu() {
    let ctx = gpu_or_skip();
    for name in ["plume", "plume_point"] {
        let scene = fixture_scene(name);
        for upsampling in [Upsampling::Trilinear, Upsampling::Physical] {
            let (cpu, gpu) = both(&ctx, &scene, &settings(upsampling));
            assert_eq!((cpu.dims, cpu.index_to_world), (gpu.dims, gpu.index_to_world));
            let lit = cpu.data.iter().filter(|v| v.max_element() > 0.0).count();
            assert!(lit > cpu.data.len() / 10, "{name}: {lit} of {} voxels lit", cpu.data.len());
            let (e, m) = (relative_rmse(&gpu.data, &cpu.data), max_rel(&gpu.data, &cpu.data));
            eprintln!("{name}, {upsampling:?}: GPU vs CPU relative RMSE {e:.2e}, largest difference {m:.2e} of the largest S");
            assert!(e < 1e-5 && m < 1e-5, "{name}, {upsampling:?}: relative RMSE {e}, largest {m}");
        }
    }
}

/// The two upsamplings differ on these tallies (so the test above compares each mode, not one
/// twice): by more than 1% relative RMSE.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_upsamplings_differ() {
    let ctx = gpu_or_skip();
    let scene = fixture_scene("plume");
    let (_, tri) = both(&ctx, &scene, &settings(Upsampling::Trilinear));
    let (_, phys) = both(&ctx, &scene, &settings(Upsampling::Physical));
    let d = relative_rmse(&phys.data, &tri.data);
    eprintln!("physical vs trilinear on the GPU: {d:.4}");
    assert!(d > 0.01, "{d}");
}

/// The whole solve on the GPU (tracing, reconstruction, exact single scattering: the defaults
/// but for the sizes) against the CPU's, with the physical upsampling, under a point light:
/// the GPU draws other random numbers (trace.wgsl), so they agree within the CPU's own seed to
/// seed difference (bound 1.5x, as tests.rs `check_against_cpu` says why).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_solve_with_physical_upsampling_matches_cpu() {
    let ctx = gpu_or_skip();
    let scene = fixture_scene("plume_point");
    let s = |seed: u64| PhotonGridSettings { seed, single_scattering: SingleScattering::Exact, ..settings(Upsampling::Physical) };
    let run = |seed: u64, backend: Box<dyn PhotonBackend>| crate::test_support::solve_on(&PhotonGrid::new(s(seed)).unwrap(), &scene, &NoProgress, &backend, None).unwrap();
    let (cpu1, cpu2) = (run(1, Box::new(CpuBackend)), run(2, Box::new(CpuBackend)));
    let gpu = run(1, Box::new(GpuPhotonBackend::new(&ctx)));
    let noise = relative_rmse(&cpu2.scattering.data, &cpu1.scattering.data);
    let e = relative_rmse(&gpu.scattering.data, &cpu1.scattering.data);
    eprintln!("whole solve, physical: GPU vs CPU {e:.4}, CPU seed 1 vs 2 {noise:.4}");
    assert!(noise > 0.0 && e < 1.5 * noise, "gpu vs cpu {e}, noise {noise}");
}

/// Bytes of the GPU reconstruction's two inputs on `scene` at `s`: the tallies (cells x lobes x
/// 48 bytes) and the bricked density.
fn input_bytes(scene: &Scene, s: &PhotonGridSettings) -> (u32, u32) {
    let cache = volscatter_core::solvers::photon_grid::cache::Cache::new(&scene.medium, s.cache_resolution).unwrap();
    ((cache.cells.len() * 2 * 48) as u32, crate::upload::bricked_density_bytes(&scene.medium) as u32)
}

/// An output whose planes do not fit one storage buffer is computed in several slabs, bit for
/// bit as in one (each voxel's arithmetic does not depend on its slab); a cache or a density
/// larger than a storage buffer is refused with `Error::Device` (so that `--device auto` falls
/// back to the CPU), before anything is allocated.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_reconstruction_slabs_and_storage_limits() {
    let mut ctx = gpu_or_skip();
    let scene = fixture_scene("plume");
    let s = settings(Upsampling::Physical);
    let (_, whole) = both(&ctx, &scene, &s);
    let plane_bytes = whole.dims[0] * whole.dims[1] * 16;
    // The storage limit lowered to what the tallies and the density need: the output's planes
    // then go in several slabs.
    let (cells_bytes, density_bytes) = input_bytes(&scene, &s);
    Arc::get_mut(&mut ctx).expect("no backend holds the context").limits.max_storage_buffer_binding_size = cells_bytes.max(density_bytes);
    let planes = ctx.limits.max_storage_buffer_binding_size / plane_bytes;
    assert!(planes >= 1 && planes * 2 < whole.dims[2], "{planes} planes a slab of {}", whole.dims[2]);
    let (_, slabs) = both(&ctx, &scene, &s);
    let bits = |v: &[Vec3]| v.iter().flat_map(|x| x.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&slabs.data), bits(&whole.data));

    let refused = |ctx: &Arc<GpuContext>, s: &PhotonGridSettings| {
        let backend: Box<dyn PhotonBackend> = Box::new(Both { gpu: GpuPhotonBackend::new(ctx), grids: Default::default() });
        crate::test_support::solve_on(&PhotonGrid::new(s.clone()).unwrap(), &scene, &NoProgress, &backend, None).err()
    };
    // The cache's tallies over the limit.
    Arc::get_mut(&mut ctx).expect("no backend holds the context").limits.max_storage_buffer_binding_size = cells_bytes - 16;
    let e = refused(&ctx, &s);
    assert!(matches!(&e, Some(Error::Device(m)) if m.contains("cache_resolution")), "{e:?}");
    // The density over it (a 2^3 cache fits).
    let small = PhotonGridSettings { cache_resolution: 2, ..s.clone() };
    Arc::get_mut(&mut ctx).expect("no backend holds the context").limits.max_storage_buffer_binding_size = input_bytes(&scene, &small).0.max(plane_bytes);
    assert!(density_bytes > ctx.limits.max_storage_buffer_binding_size);
    let e = refused(&ctx, &small);
    assert!(matches!(&e, Some(Error::Device(m)) if m.contains("density")), "{e:?}");
}

/// A cancel is seen between slabs: with the flag raised at the n-th check the reconstruction
/// returns `Cancelled` having asked no more (no slab is computed after it).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_reconstruction_stops_on_cancel() {
    use std::sync::atomic::{AtomicU32, Ordering};
    /// Cancelled once `cancelled` has been asked `after` times.
    struct CancelAfter {
        after: u32,
        asked: AtomicU32,
    }
    impl Progress for CancelAfter {
        fn update(&self, _: &str, _: f32) -> bool {
            true
        }
        fn cancelled(&self) -> bool {
            self.asked.fetch_add(1, Ordering::Relaxed) >= self.after
        }
    }
    /// Traces on the CPU and hands the tallies to the test.
    struct Keep(Arc<Mutex<Option<Vec<Tallies>>>>);
    impl PhotonBackend for Keep {
        fn trace_generations(&self, job: &TraceJob, generations: &[u64]) -> Result<Vec<Generation>> {
            CpuBackend.trace_generations(job, generations)
        }
        fn reconstruct(&self, medium: &Medium, tallies: &[Tallies], camera: Vec3, settings: &PhotonGridSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
            *self.0.lock().unwrap() = Some(tallies.to_vec());
            CpuBackend.reconstruct(medium, tallies, camera, settings, progress)
        }
    }
    let mut ctx = gpu_or_skip();
    let scene = fixture_scene("plume");
    let s = settings(Upsampling::Trilinear);
    let kept = Arc::new(Mutex::new(None));
    let keep: Box<dyn PhotonBackend> = Box::new(Keep(kept.clone()));
    let out = crate::test_support::solve_on(&PhotonGrid::new(s.clone()).unwrap(), &scene, &NoProgress, &keep, None).unwrap();
    drop(keep);
    let tallies = kept.lock().unwrap().take().unwrap();
    // Slabs of a few planes (the test above): at least 4 of them.
    let (cells_bytes, density_bytes) = input_bytes(&scene, &s);
    Arc::get_mut(&mut ctx).expect("no backend holds the context").limits.max_storage_buffer_binding_size = cells_bytes.max(density_bytes);
    let planes = ctx.limits.max_storage_buffer_binding_size / (out.scattering.dims[0] * out.scattering.dims[1] * 16);
    assert!(out.scattering.dims[2].div_ceil(planes) >= 4);
    for after in [0, 1, 3] {
        let p = CancelAfter { after, asked: AtomicU32::new(0) };
        let r = reconstruct::scattering_towards(&ctx, &scene.medium, &tallies, scene.camera.position, &s, &p);
        assert!(matches!(r, Err(Error::Cancelled)), "cancel at check {after}: {:?}", r.map(|g| g.dims));
        assert_eq!(p.asked.load(Ordering::Relaxed), after + 1);
    }
}
