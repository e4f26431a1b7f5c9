//! Measurements for `scripts/bench_photon_grid.py` (they time, never assert). Each bench
//! prints one line `BENCH_JSON {...}` that the script turns into BENCHMARKS.md's "photon-grid"
//! section. Needs the shared fixtures (volscatter-core's `testing` feature):
//!
//! cargo run --release -p volscatter-core --features testing --example bench_photon_grid -- [BENCH...]
//!
//! BENCH: a part of a bench's name (`error_vs_time`, `fig12`, `flicker`, `cloud_aim`); none: all.

use glam::{IVec3, Quat, Vec3};
use serde_json::json;
use std::time::Instant;

use volscatter_core::medium::{cumulus::cumulus_on_lattice, GridLimits, Medium};
use volscatter_core::scene::{Light, Scene};
use volscatter_core::solvers::photon_grid::{cache, Angular, PhotonGrid, PhotonGridReport, PhotonGridSettings, Similarity};
use volscatter_core::solvers::session::SessionState;
use volscatter_core::solvers::testing::{errors_against_fixture, fixture_scene as case};
use volscatter_core::solvers::{SolveCtx, SolveOutput, Solver};
use volscatter_core::stages::NoProgress;

fn emit(name: &str, v: serde_json::Value) {
    println!("BENCH_JSON {}", json!({"bench": name, "data": v}));
}

/// Error against the shared fixtures against time, for 2^14, 2^16 and 2^18 photons.
fn bench_photon_grid_error_vs_time() {
    let mut rows = Vec::new();
    for name in ["cube_g0", "cube_g09", "plume", "cloud"] {
        let sc = case(name);
        for p in [14u32, 16, 18] {
            let pg = PhotonGrid::new(PhotonGridSettings { photons: 1 << p, ..Default::default() }).unwrap();
            let t = Instant::now();
            let out = pg.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
            let secs = t.elapsed().as_secs_f64();
            let e = errors_against_fixture(name, &sc, &out.scattering);
            rows.push(json!({"scene": name, "photons": 1u64 << p, "seconds": secs, "image": e.image, "image_ratio": e.image_ratio, "grid": e.grid}));
        }
    }
    emit("error_vs_time", json!(rows));
}

/// The paper's cumulus size (48 x 62 x 90 voxels, the cumulus of medium/cumulus.rs sampled on
/// that lattice over its 2 m box, sigma_t 25, albedo 0.99, g 0.9, the dense cloud's sun).
fn paper_cumulus() -> Scene {
    let (grid, to_world) = cumulus_on_lattice(IVec3::new(48, 62, 90), GridLimits::default()).unwrap();
    let mut sc = case("cloud");
    sc.medium = Medium::new(grid, to_world, Vec3::splat(25.0), Vec3::splat(0.99), 0.9);
    sc
}

/// Paper Fig. 12's three (cells, photons) settings at m = 100: 270 / 2080 / 16640 cells (here
/// cache_resolution 9 / 18 / 36 over the 48 x 62 x 90 box) and 102 k / 819 k / 4096 k photons;
/// the time of a one-off solve (all photons) and of a session frame (photons / m).
fn bench_photon_grid_fig12() {
    let sc = paper_cumulus();
    let mut rows = Vec::new();
    for (res, photons) in [(9u32, 102_400u32), (18, 819_200), (36, 4_096_000)] {
        let s = PhotonGridSettings { photons, cache_resolution: res, generations: 100, ..Default::default() };
        let pg = PhotonGrid::new(s).unwrap();
        let cells = cache::Cache::new(&sc.medium, res).unwrap().cells.len();
        // A session's first frame is the one-off solve (all m generations).
        let mut state = SessionState::new();
        state.begin_frame();
        let t = Instant::now();
        let (one, _) = pg.solve(&sc, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).map(SolveOutput::split::<PhotonGridReport>).unwrap();
        let full = t.elapsed().as_secs_f64();
        let trace_full = one.timings.0.iter().filter(|(k, _)| k == "trace").map(|(_, v)| *v).sum::<f64>();
        let mut frame = Vec::new();
        let mut trace = Vec::new();
        for _ in 0..3 {
            state.begin_frame();
            let t = Instant::now();
            let (out, _) = pg.solve(&sc, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).map(SolveOutput::split::<PhotonGridReport>).unwrap();
            frame.push(t.elapsed().as_secs_f64());
            trace.push(out.timings.0.iter().filter(|(k, _)| k == "trace").map(|(_, v)| *v).sum::<f64>());
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        rows.push(json!({"cache_resolution": res, "cells": cells, "photons": photons, "one_off_seconds": full, "one_off_trace": trace_full,
            "frame_seconds": med(&mut frame), "frame_trace": med(&mut trace)}));
    }
    emit("fig12", json!(rows));
}

/// Flicker on a moving sun (0.5 degree per frame, 12 frames, cube g 0.7, 2^16 photons): the
/// rel. RMS change of S between consecutive frames, and the time per frame, for one-off solves
/// per frame (seed fixed, and a new seed per frame) and for sessions with m 4 and 16.
fn bench_photon_grid_flicker() {
    let frames = 12u64;
    let scene = |f: u64| {
        let mut sc = case("cube_g07");
        for l in &mut sc.lights {
            if let Light::Distant { direction, .. } = l {
                *direction = Quat::from_rotation_z((0.5 * f as f32).to_radians()) * *direction;
            }
        }
        sc
    };
    let rel = |a: &[Vec3], b: &[Vec3]| {
        let (mut n, mut d) = (0.0f64, 0.0f64);
        for (x, y) in a.iter().zip(b) {
            n += (*x - *y).as_dvec3().length_squared();
            d += y.as_dvec3().length_squared();
        }
        (n / d).sqrt()
    };
    let base = PhotonGridSettings { photons: 1 << 16, cache_resolution: 16, output_resolution: 32, ..Default::default() };
    let mut rows = Vec::new();
    for (label, m, new_seed) in [("one-off, fixed seed", 1u32, false), ("one-off, new seed per frame", 1, true), ("session m 4", 4, false), ("session m 16", 16, false)] {
        let mut state = SessionState::new();
        let mut prev: Option<Vec<Vec3>> = None;
        let (mut changes, mut secs) = (Vec::new(), Vec::new());
        for f in 0..frames {
            let s = PhotonGridSettings { generations: m, seed: if new_seed { 1 + f } else { 1 }, ..base.clone() };
            let pg = PhotonGrid::new(s).unwrap();
            state.begin_frame();
            let t = Instant::now();
            let (out, _) = pg.solve(&scene(f), &mut SolveCtx::new(&NoProgress).in_session(&mut state)).map(SolveOutput::split::<PhotonGridReport>).unwrap();
            if f > 0 {
                secs.push(t.elapsed().as_secs_f64());
            }
            if let Some(p) = &prev {
                changes.push(rel(&out.scattering.data, p));
            }
            prev = Some(out.scattering.data);
        }
        let rms = (changes.iter().map(|c| c * c).sum::<f64>() / changes.len() as f64).sqrt();
        rows.push(json!({"run": label, "generations": m, "flicker": rms, "frame_seconds": secs.iter().sum::<f64>() / secs.len() as f64}));
    }
    emit("flicker", json!(rows));
}

/// The aim on the dense cloud: time against image error for photon-grid (the
/// defaults at 2^16 to 2^22 photons, and `angular: camera` with the similarity switch off and
/// cache 32 at 2^18 to 2^24), and for the reference path tracer at 256 to 4096 paths per
/// pixel, both against the cloud fixture (own noise 2.2%). PG_BENCH_MAX_PHOTONS caps the
/// defaults' photon count (log2, default 22; the camera rows go 2 further).
fn bench_photon_grid_cloud_aim() {
    use volscatter_core::solvers::reference::{Reference, ReferenceSettings};
    use volscatter_core::solvers::testing::{env_u32, load_fixture, rgb, Errors};
    let sc = case("cloud");
    let fx = load_fixture("cloud");
    let mut rows = Vec::new();
    for spp in [256u32, 1024, 4096] {
        let t = Instant::now();
        let r = Reference::new(ReferenceSettings { spp, transparent: true, ..Default::default() }).unwrap();
        let img = r.render_image(&sc, &mut SolveCtx::new(&NoProgress), false, &mut volscatter_core::stages::Timings::default()).expect("the reference renders images").unwrap();
        let secs = t.elapsed().as_secs_f64();
        let e = Errors::between(&rgb(&img), &[], &[], &fx.image(), &[], None);
        rows.push(json!({"method": "reference", "spp": spp, "seconds": secs, "image": e.image, "image_ratio": e.image_ratio}));
    }
    let max = env_u32("PG_BENCH_MAX_PHOTONS", 22);
    let camera = PhotonGridSettings { angular: Angular::Camera, similarity: Similarity::Off, cache_resolution: 32, ..Default::default() };
    for (label, s, from, to) in [("defaults", PhotonGridSettings::default(), 16, max), ("camera, similarity off, cache 32", camera, 18, max + 2)] {
        for p in (from..=to).step_by(2) {
            let pg = PhotonGrid::new(PhotonGridSettings { photons: 1 << p, ..s.clone() }).unwrap();
            let t = Instant::now();
            let out = pg.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
            let secs = t.elapsed().as_secs_f64();
            let e = errors_against_fixture("cloud", &sc, &out.scattering);
            rows.push(json!({"method": format!("photon-grid {label}"), "photons": 1u64 << p, "seconds": secs, "image": e.image, "image_ratio": e.image_ratio, "grid": e.grid}));
        }
    }
    emit("cloud_aim", json!({"rows": rows, "fixture_noise": fx.noise_image}));
}

/// Runs the benches named on the command line (a name's part selects; none: all), in order.
fn main() {
    let only: Vec<String> = std::env::args().skip(1).collect();
    let benches: [(&str, fn()); 4] = [("bench_photon_grid_error_vs_time", bench_photon_grid_error_vs_time), ("bench_photon_grid_fig12", bench_photon_grid_fig12), ("bench_photon_grid_flicker", bench_photon_grid_flicker), ("bench_photon_grid_cloud_aim", bench_photon_grid_cloud_aim)];
    for (name, bench) in benches {
        if only.is_empty() || only.iter().any(|o| name.contains(o.as_str())) {
            eprintln!("{name}");
            bench();
        }
    }
}
