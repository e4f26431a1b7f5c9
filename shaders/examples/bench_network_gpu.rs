//! Measurements for `scripts/bench_network.py --gpu-only` (it times, never asserts). Prints one
//! line `BENCH_JSON {...}` with the adapter's name, whether it is a software one (lavapipe:
//! correctness only, not GPU speed), and absolute times of the CPU and GPU backends on the same
//! scenes, so that a session with a real GPU only reruns it.
//!
//! cargo run --release -p volscatter-gpu --example bench_network_gpu (`NETWORK_BENCH_QUICK=1`:
//! small sizes only).

use glam::Vec3;
use serde_json::json;
use std::time::Instant;

use std::sync::Arc;
use volscatter_gpu::network::{GpuBackend, CHECK_EVERY};
use volscatter_gpu::GpuContext;
use volscatter_core::image::relative_rmse;
use volscatter_core::medium::{cumulus, GridLimits, Medium};
use volscatter_core::scene::{Camera, Environment, Light};
use volscatter_core::solvers::network::backend::{CpuBackend, NetworkBackend};
use volscatter_core::solvers::network::{particles, Network, NetworkReport, NetworkSettings};
use volscatter_core::solvers::{SolveCtx, SolveOutput, Solver};
use volscatter_core::stages::NoProgress;
use volscatter_core::translate::sampling::BoundingSphere;
use volscatter_core::Scene;

/// `solver` solved one-off with `backend` as the device's entry (as the kernel tests'
/// test_support.rs `solve_on`).
fn solve_on<B: ?Sized + 'static>(solver: &dyn Solver, scene: &Scene, backend: &Box<B>) -> volscatter_core::Result<SolveOutput> {
    solver.solve(scene, &mut SolveCtx::new(&NoProgress).on(backend))
}

/// The GPU context; the bench is for a machine that has one.
fn gpu() -> Arc<GpuContext> {
    Arc::new(GpuContext::new().unwrap_or_else(|e| panic!("this bench needs a usable GPU adapter: {e}")))
}

/// The paper's cloud as core's examples/bench_network.rs builds it (Sec. 5: 2 R tau = 20, albedo 0.9,
/// g 0, two distant lights and a sky) on the procedural cumulus of the dense-cloud fixture
/// (64 voxels per side), with its own camera.
fn paper_cloud() -> Scene {
    let (grid, to_world) = cumulus::cumulus(64, GridLimits::default()).unwrap();
    let mut medium = Medium::new(grid, to_world, Vec3::splat(25.0), Vec3::splat(0.9), 0.0);
    let p = particles::sample(&medium, 2048, 1);
    let sphere = BoundingSphere::of(&medium);
    medium.density_scale *= 10.0 / (sphere.radius * p.mean_sigma_t);
    Scene {
        medium,
        lights: vec![
            Light::Distant { direction: Vec3::new(0.6, 0.0, -0.8), irradiance: Vec3::splat(2.0), half_angle: 0.0 },
            Light::Distant { direction: Vec3::new(-0.5, 0.3, 0.81).normalize(), irradiance: Vec3::splat(1.0), half_angle: 0.0 },
            Light::Dome(Environment { color: Vec3::new(0.2, 0.3, 0.5), map: None }),
        ],
        camera: Camera::look_at(sphere.center + Vec3::new(0.0, -4.0, 0.6) * sphere.radius, sphere.center, Vec3::Z, 30.0, 24, 24),
        solver: Default::default(),
    }
}

fn phase(out: &SolveOutput, name: &str) -> f64 {
    out.timings.0.iter().filter(|(k, _)| k == name).map(|(_, v)| *v).sum()
}

/// One solve on `backend`: wall seconds of the visibility network, of the iteration, of the
/// splat, of the whole solve, and the iterations; with the solve's output.
fn timed(sc: &Scene, s: &NetworkSettings, backend: &Box<dyn NetworkBackend>) -> (serde_json::Value, SolveOutput) {
    let t = Instant::now();
    let net = Network::new(s.clone()).unwrap();
    let (out, rep) = solve_on(&net, sc, backend).unwrap().split::<NetworkReport>();
    let total = t.elapsed().as_secs_f64();
    let iterate = phase(&out, "network iterate");
    let iterations = rep.residuals.len();
    let row = json!({"iterations": iterations, "visibility_seconds": phase(&out, "network visibility"), "iterate_seconds": iterate,
           "per_iteration_ms": 1e3 * iterate / iterations.max(1) as f64, "splat_seconds": phase(&out, "network splat"), "solve_seconds": total});
    (row, out)
}

fn main() {
    let ctx = gpu();
    let quick = std::env::var("NETWORK_BENCH_QUICK").is_ok_and(|v| v == "1");
    let sc = paper_cloud();
    let gpu: Box<dyn NetworkBackend> = Box::new(GpuBackend::new(&ctx, CHECK_EVERY));
    let cpu: Box<dyn NetworkBackend> = Box::new(CpuBackend);
    let mut sizes = vec![(512u32, 128u32, 32u32), (1024, 128, 32), (2048, 64, 64)];
    if !quick {
        sizes.extend([(8192, 128, 64), (8192, 128, 128), (32768, 256, 128)]);
    }
    // Compiles the pipelines outside the timings.
    let warm = NetworkSettings { particles: 256, directions: 16, output_resolution: 8, ..Default::default() };
    solve_on(&Network::new(warm).unwrap(), &sc, &gpu).unwrap();
    let mut rows = Vec::new();
    for (n, d, res) in sizes {
        let s = NetworkSettings { particles: n, directions: d, output_resolution: res, ..Default::default() };
        let ((cpu, cpu_out), (gpu_row, gpu_out)) = (timed(&sc, &s, &cpu), timed(&sc, &s, &gpu));
        let error = relative_rmse(&gpu_out.scattering.data, &cpu_out.scattering.data);
        rows.push(json!({"particles": n, "directions": d, "output_resolution": res, "cpu": cpu, "gpu": gpu_row, "s_rel_rmse": error}));
    }
    let data = json!({"device": ctx.describe(), "software": ctx.is_software(), "quick": quick, "rows": rows});
    println!("BENCH_JSON {}", json!({"bench": "gpu", "data": data}));
}
