use super::*;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use glam::Vec3;
use volscatter_core::image::relative_rmse;
use volscatter_core::scene::Light;
use volscatter_core::solvers::photon_grid::backend::CpuBackend;
use volscatter_core::solvers::photon_grid::{PhotonGrid, PhotonGridReport, PhotonGridSettings, SingleScattering};
use volscatter_core::solvers::session::SessionState;
use volscatter_core::solvers::{SolveOutput};
use volscatter_core::stages::NoProgress;
use volscatter_core::Scene;

#[test]
fn wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(WGSL, "Params") as usize, size_of::<TraceParams>());
}

/// Every order from photons (no compositor) so that S is the photons' alone, on a cache small
/// enough for lavapipe.
fn settings(photons: u32, seed: u64) -> PhotonGridSettings {
    PhotonGridSettings { photons, seed, cache_resolution: 12, output_resolution: 24, single_scattering: SingleScattering::Photons, ..Default::default() }
}

fn solve(scene: &Scene, s: PhotonGridSettings, backend: &Box<dyn PhotonBackend>) -> (SolveOutput, PhotonGridReport) {
    crate::test_support::solve_on(&PhotonGrid::new(s).unwrap(), scene, &NoProgress, backend, None).unwrap().split()
}

fn rgb_rel(a: DVec3, b: DVec3) -> f64 {
    (a - b).length() / b.length().max(1e-30)
}

/// GPU and CPU draw different random numbers (trace.wgsl), so they agree in distribution:
/// the GPU's S differs from the CPU's of the same seed by about as much as two CPU seeds
/// differ (both are one sample of the same estimator's noise: same rays' distribution, same
/// majorant grids, same tracking and scattering). Bound: 1.5x the CPU's seed-to-seed
/// relative RMSE (at 2^15 photons the ratio of two such RMSEs scatters by ~10%, so 1.5 leaves
/// room; a bias of the order of the noise fails it). Energy: in grey media the GPU's own balance
/// escaped + absorbed + cut = emitted within 1e-5 (the fixed-point sums' rounding is 2^-28 of
/// a photon), and its escaped energy within 3% of the CPU's (the noise of 2^15 photons' escape
/// fraction, ~0.5%, with room). Scattering counts within 5% (their noise at 2^15 photons is
/// ~2% on the plume, where most photons miss and a few scatter many times). Measured with more photons, where a bias would stand out of the noise: at 2^20 on the
/// plume, S 2.2% from the CPU's against 2.7% between two CPU seeds, mean S x0.994 (CPU seeds
/// x0.999), scatterings 583199 against 586425 / 584916 (noise ~2000); at 2^18 with the point
/// light and chromatic medium, S 0.66% against 0.77%, scatterings +0.18%.
fn check_against_cpu(what: &str, scene: &Scene) {
    let ctx = gpu_or_skip();
    let n = 1 << 15;
    let (cpu1, rep1) = solve(scene, settings(n, 1), &(Box::new(CpuBackend) as Box<dyn PhotonBackend>));
    let (cpu2, _) = solve(scene, settings(n, 2), &(Box::new(CpuBackend) as Box<dyn PhotonBackend>));
    let (gpu, rep) = solve(scene, settings(n, 1), &(Box::new(GpuPhotonBackend::new(&ctx)) as Box<dyn PhotonBackend>));
    let noise = relative_rmse(&cpu2.scattering.data, &cpu1.scattering.data);
    let e = relative_rmse(&gpu.scattering.data, &cpu1.scattering.data);
    eprintln!("{what}: S relative RMSE gpu vs cpu {e:.4}, cpu seed 1 vs 2 {noise:.4}");
    assert!(noise > 0.0 && e < 1.5 * noise, "{what}: gpu vs cpu {e}, noise {noise}");
    let (g, c) = (rep.energy, rep1.energy);
    eprintln!("{what}: gpu energy {g:?}\n{what}: cpu energy {c:?}");
    assert_eq!(g.photons, c.photons, "{what}");
    assert!(rgb_rel(g.emitted, c.emitted) < 0.05, "{what}: emitted {} vs {}", g.emitted, c.emitted);
    // Spectral tracking's weights conserve energy only in expectation: the balance is exact
    // per photon in grey media only.
    let m = &scene.medium;
    if m.density_scale.min_element() == m.density_scale.max_element() {
        let balance = rgb_rel(g.escaped + g.absorbed + g.cut, g.emitted);
        assert!(balance < 1e-5, "{what}: gpu energy balance {balance}");
    }
    let escaped = rgb_rel(g.escaped, c.escaped);
    assert!(escaped < 0.03, "{what}: escaped gpu {} cpu {}", g.escaped, c.escaped);
    let sc = (g.scatterings as f64 - c.scatterings as f64).abs() / c.scatterings.max(1) as f64;
    assert!(sc < 0.05, "{what}: scatterings gpu {} cpu {}", g.scatterings, c.scatterings);
}

#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_tracing_matches_cpu_on_the_default_plume() {
    // The plume (g 0.9, albedo 0.99) with its sun and dome: the similarity switch and the
    // cutoff both taken.
    check_against_cpu("plume, sun + dome", &Scene::default_scene());
}

#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_tracing_matches_cpu_with_a_local_light() {
    let mut scene = Scene::default_scene();
    scene.lights = vec![Light::Point { position: Vec3::new(0.1, -0.2, 0.0), intensity: Vec3::new(3.0, 2.0, 1.0), radius: 0.0, interior: Default::default() }];
    // Chromatic extinction and albedo: spectral tracking's weights.
    scene.medium.density_scale *= Vec3::new(1.0, 0.8, 0.6);
    scene.medium.albedo = Vec3::new(0.99, 0.95, 0.9);
    check_against_cpu("point light, chromatic medium", &scene);
}

/// Integer atomics make a generation's tallies independent of the order invocations add in:
/// two GPU solves are equal bit for bit, and a session's ring m frames after a light step is
/// bit for bit the fresh solve of the same generations (ring.rs), as on the CPU.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_tracing_is_exact_run_to_run_and_through_the_ring() {
    let ctx = gpu_or_skip();
    let backend: Box<dyn PhotonBackend> = Box::new(GpuPhotonBackend::new(&ctx));
    let mut scene = Scene::default_scene();
    let s = PhotonGridSettings { generations: 3, ..settings(1 << 13, 5) };
    let (a, _) = solve(&scene, s.clone(), &backend);
    let (b, _) = solve(&scene, s.clone(), &backend);
    assert!(a.scattering.data.iter().zip(&b.scattering.data).all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
    assert!(a.scattering.data.iter().any(|v| v.x > 0.0));

    let solver = PhotonGrid::new(s.clone()).unwrap();
    let mut state = SessionState::new();
    crate::test_support::solve_on(&solver, &scene, &NoProgress, &backend, Some(&mut state)).unwrap();
    if let Some(Light::Distant { irradiance, .. }) = scene.lights.iter_mut().find(|l| matches!(l, Light::Distant { .. })) {
        *irradiance *= 2.0;
    } else {
        panic!("the default scene has a sun");
    }
    let mut last = None;
    for _ in 0..3 {
        state.begin_frame();
        last = Some(crate::test_support::solve_on(&solver, &scene, &NoProgress, &backend, Some(&mut state)).unwrap().split::<PhotonGridReport>());
    }
    let (ring, rep) = last.unwrap();
    assert_eq!(rep.generations, vec![3, 4, 5]);
    let fresh = crate::test_support::solve_on(&solver.from_generation(3), &scene, &NoProgress, &backend, None).unwrap();
    assert_eq!(ring.scattering.data, fresh.scattering.data);
}

/// A host's cancel stops the GPU trace between dispatches: the solve returns `Cancelled`
/// (the flag here is raised before the first dispatch; progress callbacks still answer yes).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_tracing_stops_on_cancel() {
    struct Cancelled;
    impl volscatter_core::stages::Progress for Cancelled {
        fn update(&self, _: &str, _: f32) -> bool {
            true
        }
        fn cancelled(&self) -> bool {
            true
        }
    }
    let ctx = gpu_or_skip();
    let solver = PhotonGrid::new(settings(1 << 16, 1)).unwrap();
    let gpu: Box<dyn PhotonBackend> = Box::new(GpuPhotonBackend::new(&ctx));
    let r = crate::test_support::solve_on(&solver, &Scene::default_scene(), &Cancelled, &gpu, None);
    assert!(matches!(r, Err(Error::Cancelled)), "{:?}", r.err());
}

/// The host's path (`solve` with `--device gpu`, the CLI's and the C ABI's entry point) runs
/// photon-grid's GPU backend, exact single scattering included (the compositor's GPU kernel,
/// within 1e-5 of the CPU's): the result is the CPU's within noise (the same bound as `check_against_cpu`, against the
/// CPU's seed-to-seed relative RMSE).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn device_gpu_runs_the_gpu_backend() {
    use crate::device::{DeviceChoice, DeviceUsed};
    let scene = Scene::default_scene();
    let map = |seed: u64| serde_json::json!({"photons": 1 << 14, "seed": seed, "cache_resolution": 12, "output_resolution": 24}).as_object().unwrap().clone();
    let (gpu, used) = crate::test_support::solve(DeviceChoice::Gpu, &scene, "photon-grid", &map(1), &NoProgress).unwrap();
    assert!(matches!(used, DeviceUsed::Gpu(_)), "ran on {used}");
    let (cpu1, _) = crate::test_support::solve(DeviceChoice::Cpu, &scene, "photon-grid", &map(1), &NoProgress).unwrap();
    let (cpu2, _) = crate::test_support::solve(DeviceChoice::Cpu, &scene, "photon-grid", &map(2), &NoProgress).unwrap();
    let noise = relative_rmse(&cpu2.scattering.data, &cpu1.scattering.data);
    let e = relative_rmse(&gpu.scattering.data, &cpu1.scattering.data);
    eprintln!("--device gpu: S relative RMSE against the CPU {e:.4}, CPU seed to seed {noise:.4}");
    assert!(noise > 0.0 && e < 1.5 * noise, "gpu vs cpu {e}, noise {noise}");
}

/// The workgroup pre-sum (trace.wgsl) changes only where the integer additions happen: with
/// it on and off the same photons give the same 64-bit sums, so S and the energy report are
/// equal bit for bit. Cache 12 (3456 keys against the table's 160 slots: many deposits miss
/// the table and go to device memory directly) and cache 3 (every cell has a slot).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn workgroup_presum_is_bit_exact() {
    let ctx = gpu_or_skip();
    let scene = Scene::default_scene();
    for cache_resolution in [12, 3] {
        let s = PhotonGridSettings { cache_resolution, ..settings(1 << 14, 3) };
        let (a, ra) = solve(&scene, s.clone(), &(Box::new(GpuPhotonBackend::new(&ctx)) as Box<dyn PhotonBackend>));
        let (b, rb) = solve(&scene, s, &(Box::new(GpuPhotonBackend { presum: false, ..GpuPhotonBackend::new(&ctx) }) as Box<dyn PhotonBackend>));
        let bits = |v: &[Vec3]| v.iter().flat_map(|x| x.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        assert!(a.scattering.data.iter().any(|v| v.x > 0.0));
        assert_eq!(bits(&a.scattering.data), bits(&b.scattering.data), "cache {cache_resolution}");
        let (ea, eb) = (ra.energy, rb.energy);
        assert_eq!((ea.escaped, ea.absorbed, ea.cut, ea.scatterings, ea.switched), (eb.escaped, eb.absorbed, eb.cut, eb.scatterings, eb.switched), "cache {cache_resolution}");
    }
}
