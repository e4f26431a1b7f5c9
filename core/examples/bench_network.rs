//! Measurements for `scripts/bench_network.py` (they time, never assert). Each bench prints
//! one line `BENCH_JSON {...}` that the script turns into BENCHMARKS.md's "network" section.
//! Needs the shared fixtures (volscatter-core's `testing` feature):
//!
//! cargo run --release -p volscatter-core --features testing --example bench_network -- [BENCH...]
//!
//! BENCH: a part of a bench's name (`error_vs_time`, `paper_cloud`); none: all.

use glam::{Quat, Vec3};
use serde_json::json;
use std::time::Instant;

use volscatter_core::scene::{Camera, Environment, Light, Scene};
use volscatter_core::solvers::network::{particles, Network, NetworkReport, NetworkSettings, Start};
use volscatter_core::solvers::session::SessionState;
use volscatter_core::solvers::testing::{cloud::cloud_scene, errors_against_fixture, fixture_scene};
use volscatter_core::solvers::{SolveOutput, SolveCtx, Solver};
use volscatter_core::stages::NoProgress;
use volscatter_core::translate::sampling::BoundingSphere;

fn emit(name: &str, v: serde_json::Value) {
    println!("BENCH_JSON {}", json!({"bench": name, "data": v}));
}

fn phase(out: &SolveOutput, name: &str) -> f64 {
    out.timings.0.iter().filter(|(k, _)| k == name).map(|(_, v)| *v).sum()
}

/// Error against the shared fixtures against time, N 1024 / 2048 / 4096 (D 64).
fn bench_network_error_vs_time() {
    let mut rows = Vec::new();
    for (name, sc) in [("cube_g0", fixture_scene("cube_g0")), ("cube_g09", fixture_scene("cube_g09")), ("plume", fixture_scene("plume")), ("cloud", cloud_scene())] {
        for n in [1024u32, 2048, 4096] {
            let s = NetworkSettings { particles: n, output_resolution: 32, ..Default::default() };
            let t = Instant::now();
            let (out, rep) = Network::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
            let secs = t.elapsed().as_secs_f64();
            let e = errors_against_fixture(name, &sc, &out.scattering);
            rows.push(json!({"scene": name, "particles": n, "seconds": secs, "image": e.image, "image_ratio": e.image_ratio, "grid": e.grid, "window": rep.window, "iterations": rep.residuals.len()}));
        }
    }
    emit("error_vs_time", json!(rows));
}

/// The paper's cloud (Sec. 5: 2 R tau = 20, albedo 0.9, g 0, two distant lights and a sky):
/// the cumulus with its extinction scaled so that the bounding radius times the particles'
/// mean extinction is 10.
fn paper_cloud() -> Scene {
    let mut sc = cloud_scene();
    let p = particles::sample(&sc.medium, 2048, 1);
    let r = BoundingSphere::of(&sc.medium).radius;
    sc.medium.density_scale *= 10.0 / (r * p.mean_sigma_t);
    sc.medium.albedo = Vec3::splat(0.9);
    sc.medium.g = 0.0;
    sc.lights = vec![
        Light::Distant { direction: Vec3::new(0.6, 0.0, -0.8), irradiance: Vec3::splat(2.0), half_angle: 0.0 },
        Light::Distant { direction: Vec3::new(-0.5, 0.3, 0.81).normalize(), irradiance: Vec3::splat(1.0), half_angle: 0.0 },
        Light::Dome(Environment { color: Vec3::new(0.2, 0.3, 0.5), map: None }),
    ];
    sc
}

/// Time per iteration on the paper's cloud, N 512 and 1024, D 128, and the phases of a solve;
/// then a camera orbit (12 frames of 30 degrees) in a session against full solves.
fn bench_network_paper_cloud() {
    let sc = paper_cloud();
    let mut rows = Vec::new();
    for n in [512u32, 1024] {
        let s = NetworkSettings { particles: n, directions: 128, output_resolution: 32, ..Default::default() };
        let net = Network::new(s).unwrap();
        let t = Instant::now();
        let (out, rep) = net.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
        let total = t.elapsed().as_secs_f64();
        let iterate = phase(&out, "network iterate");
        let mut state = SessionState::new();
        state.begin_frame();
        net.solve(&sc, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).map(SolveOutput::split::<NetworkReport>).unwrap();
        let (mut orbit, mut full) = (Vec::new(), Vec::new());
        for f in 1..=6 {
            let mut moved = sc.clone();
            let pos = Quat::from_rotation_z((30.0 * f as f32).to_radians()) * sc.camera.position;
            moved.camera = Camera::look_at(pos, Vec3::new(0.0, 0.0, 0.1), Vec3::Z, 21.0, sc.camera.width, sc.camera.height);
            state.begin_frame();
            let t = Instant::now();
            let (_, r) = net.solve(&moved, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).map(SolveOutput::split::<NetworkReport>).unwrap();
            orbit.push(t.elapsed().as_secs_f64());
            assert_eq!(r.start, Start::Kept);
            let t = Instant::now();
            net.solve(&moved, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<NetworkReport>).unwrap();
            full.push(t.elapsed().as_secs_f64());
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        rows.push(json!({"particles": n, "directions": 128, "window": rep.window, "iterations": rep.residuals.len(), "solve_seconds": total,
            "iterate_seconds": iterate, "per_iteration_ms": 1e3 * iterate / rep.residuals.len().max(1) as f64,
            "visibility_seconds": phase(&out, "network visibility"), "direct_seconds": phase(&out, "network direct"),
            "orbit_frame_seconds": mean(&orbit), "full_solve_seconds": mean(&full)}));
    }
    emit("paper_cloud", json!(rows));
}

/// Runs the benches named on the command line (a name's part selects; none: all), in order.
fn main() {
    let only: Vec<String> = std::env::args().skip(1).collect();
    let benches: [(&str, fn()); 2] = [("bench_network_error_vs_time", bench_network_error_vs_time), ("bench_network_paper_cloud", bench_network_paper_cloud)];
    for (name, bench) in benches {
        if only.is_empty() || only.iter().any(|o| name.contains(o.as_str())) {
            eprintln!("{name}");
            bench();
        }
    }
}
