//! Measurements for `scripts/bench_photon_grid.py --gpu` (it times, never asserts). Prints one
//! line `BENCH_JSON {...}`: paper Fig. 12's three (cells, photons) settings on the 48 x 62 x 90
//! cumulus, the tracing and reconstruction stages on the CPU backend and on the GPU backend, for
//! a one-off solve (all photons) and for a session frame's share (photons / m, m = 100), then
//! the reconstruction alone at the cumulus's resolution with each upsampling, with the adapter's
//! name. `VOLSCATTER_BENCH_QUICK=1`: the first setting only.
//!
//! cargo run --release -p volscatter-gpu --example bench_photon_grid_gpu

use glam::{IVec3, Vec3};
use serde_json::json;
use std::time::Instant;

use volscatter_gpu::photon_grid::GpuPhotonBackend;
use volscatter_core::medium::{cumulus::cumulus_on_lattice, GridLimits, Medium};
use volscatter_core::scene::{Camera, Light};
use volscatter_core::solvers::photon_grid::backend::{CpuBackend, PhotonBackend};
use volscatter_core::solvers::photon_grid::{PhotonGrid, PhotonGridSettings, Upsampling};
use volscatter_core::stages::NoProgress;
use volscatter_core::Scene;
use std::sync::Arc;
use volscatter_core::solvers::{SolveCtx, SolveOutput, Solver};
use volscatter_gpu::GpuContext;

/// `solver` solved one-off with `backend` as the device's entry (as the kernel tests'
/// test_support.rs `solve_on`).
fn solve_on<B: ?Sized + 'static>(solver: &dyn Solver, scene: &Scene, backend: &Box<B>) -> volscatter_core::Result<SolveOutput> {
    solver.solve(scene, &mut SolveCtx::new(&NoProgress).on(backend))
}

/// The GPU context; the bench is for a machine that has one.
fn gpu() -> Arc<GpuContext> {
    Arc::new(GpuContext::new().unwrap_or_else(|e| panic!("this bench needs a usable GPU adapter: {e}")))
}

/// The cumulus of core's examples/bench_photon_grid.rs `paper_cumulus`: sigma_t 25, albedo 0.99, g 0.9,
/// lit by the dense cloud's sun (45 degrees up, from +x and the camera's side).
fn paper_cumulus() -> Scene {
    let (grid, to_world) = cumulus_on_lattice(IVec3::new(48, 62, 90), GridLimits::default()).unwrap();
    let e = 45f32.to_radians();
    let to_sun = (Vec3::new(0.8, -0.6, 0.0) * e.cos() + Vec3::Z * e.sin()).normalize();
    Scene {
        medium: Medium::new(grid, to_world, Vec3::splat(25.0), Vec3::splat(0.99), 0.9),
        lights: vec![Light::Distant { direction: -to_sun, irradiance: Vec3::splat(3.0), half_angle: 0.0 }],
        camera: Camera::look_at(Vec3::new(0.0, -6.0, 0.2), Vec3::new(0.0, 0.0, 0.1), Vec3::Z, 21.0, 64, 64),
        solver: Default::default(),
    }
}

/// (trace seconds, reconstruction seconds, whole solve seconds) of a one-off solve.
fn timed(scene: &Scene, s: &PhotonGridSettings, backend: &Box<dyn PhotonBackend>) -> (f64, f64, f64) {
    let t = Instant::now();
    let out = solve_on(&PhotonGrid::new(s.clone()).unwrap(), scene, backend).unwrap();
    let total = t.elapsed().as_secs_f64();
    let stage = |name: &str| out.timings.0.iter().filter(|(k, _)| k == name).map(|(_, v)| *v).sum();
    (stage("trace"), stage("reconstruct"), total)
}

fn main() {
    let ctx = gpu();
    let gpu: Box<dyn PhotonBackend> = Box::new(GpuPhotonBackend::new(&ctx));
    let cpu: Box<dyn PhotonBackend> = Box::new(CpuBackend);
    let scene = paper_cumulus();
    let quick = std::env::var("VOLSCATTER_BENCH_QUICK").is_ok_and(|v| v == "1");
    let settings: &[(u32, u32)] = if quick { &[(9, 102_400)] } else { &[(9, 102_400), (18, 819_200), (36, 4_096_000)] };
    // Warm-up: the pipeline's compilation is not part of a frame.
    timed(&scene, &PhotonGridSettings { photons: 1024, ..Default::default() }, &gpu);
    let mut rows = Vec::new();
    for &(res, photons) in settings {
        for (what, n) in [("one-off", photons), ("frame (photons / 100)", photons / 100)] {
            let s = PhotonGridSettings { photons: n, cache_resolution: res, ..Default::default() };
            let (cpu_trace, cpu_reconstruct, cpu_total) = timed(&scene, &s, &cpu);
            let (gpu_trace, gpu_reconstruct, gpu_total) = timed(&scene, &s, &gpu);
            rows.push(json!({"cache_resolution": res, "photons": n, "run": what, "cpu_trace": cpu_trace, "cpu_total": cpu_total,
                "gpu_trace": gpu_trace, "gpu_total": gpu_total, "cpu_reconstruct": cpu_reconstruct, "gpu_reconstruct": gpu_reconstruct}));
        }
    }
    // The reconstruction alone at the cumulus's own resolution (90 planes: output 90), both
    // upsamplings: its cost depends on the output and the cache, not on the photons. The
    // fastest of 3 solves (a shared machine's other jobs only ever add time).
    let mut reconstruct = Vec::new();
    for upsampling in [Upsampling::Trilinear, Upsampling::Physical] {
        let s = PhotonGridSettings { photons: 102_400, cache_resolution: 18, output_resolution: 90, upsampling, ..Default::default() };
        let best = |backend: &Box<dyn PhotonBackend>| (0..3).map(|_| timed(&scene, &s, backend).1).fold(f64::INFINITY, f64::min);
        let (cpu_s, gpu_s) = (best(&cpu), best(&gpu));
        reconstruct.push(json!({"upsampling": format!("{upsampling:?}").to_lowercase(), "cache_resolution": 18, "output_resolution": 90,
            "cpu_reconstruct": cpu_s, "gpu_reconstruct": gpu_s}));
    }
    let doc = json!({"bench": "gpu", "data": {"device": ctx.describe(), "software": ctx.is_software(), "rows": rows, "reconstruct": reconstruct}});
    println!("BENCH_JSON {doc}");
}
