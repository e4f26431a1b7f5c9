//! lpm against the white furnace, exact single scattering, the converged reference fixtures,
//! and itself (streamed against in-memory, convergence in directions, resolution, orders).

use glam::Vec3;

use super::{FirstOrder, Lpm, LpmReport, LpmSettings, Overrides};
use crate::scene::{Camera, Environment, Light, Scene};
use crate::solvers::testing::{errors_against_fixture, homogeneous_box, s_over_sigma_s};
use crate::solvers::{NoProgress, ScatteringGrid};

/// The fixtures' scenes (as vpl/tests.rs).
fn case(name: &str) -> Scene {
    if name == "cloud" {
        crate::solvers::testing::cloud::cloud_scene()
    } else if name.starts_with("plume_") || name.starts_with("fig10") {
        crate::solvers::pop::radial::tests::case(name)
    } else {
        crate::solvers::pop::tests::case(name)
    }
}

fn run(sc: &Scene, s: LpmSettings, ov: Overrides) -> (ScatteringGrid, LpmReport) {
    let (out, rep) = Lpm::new(s).unwrap().solve_detailed(sc, &NoProgress, ov).unwrap();
    (out.scattering, rep)
}

/// The furnace box: 8^3 voxels of 0.125 m, optical thickness 4 across, g 0.6, white, under a
/// uniform dome of radiance 1 (as testing/furnace.rs).
fn furnace_box(g: f32) -> Scene {
    Scene {
        medium: homogeneous_box(8, 0.125, 4.0, 1.0, g),
        lights: vec![Light::Dome(Environment { color: Vec3::ONE, map: None })],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 12, 12),
        solver: Default::default(),
    }
}

fn mean(v: &[f32]) -> f64 {
    v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64
}

/// White furnace run to epsilon: the radiance is 1 everywhere inside, so S / sigma_s = 1 in
/// the box's interior. Within 1%.
#[test]
fn lpm_white_furnace_to_epsilon() {
    for g in [0.0f32, 0.6] {
        let sc = furnace_box(g);
        let s = LpmSettings { grid_resolution: 24, output_resolution: 10, epsilon: 1e-4, max_orders: 2000, ..Default::default() };
        let t = std::time::Instant::now();
        let (grid, rep) = run(&sc, s, Overrides::default());
        let m = mean(&s_over_sigma_s(&grid, &sc.medium, 0.99));
        eprintln!("g {g}: white furnace S / sigma_s {m:.4} after {} orders, {:.2} s", rep.orders, t.elapsed().as_secs_f64());
        assert!((m - 1.0).abs() < 0.01, "g {g}: {m}");
    }
}

/// Streamed equals in-memory: slabs of 4, 8, 16 layers and the whole volume give the same J
/// (the same arithmetic in the same order: equal to the bit, asserted within 1e-6
/// relative), and the working memory is the maps plus one slab.
#[test]
fn lpm_streamed_equals_in_memory() {
    let sc = case("plume");
    let s = LpmSettings { grid_resolution: 24, directions: 9, max_orders: 3, ..Default::default() };
    let ov = |layers| Overrides { layers, j_only: true, ..Default::default() };
    let (_, whole) = run(&sc, s.clone(), ov(None));
    let jw = whole.j.as_ref().unwrap();
    let top = jw.data.iter().fold(0.0f32, |a, v| a.max(v.max_element()));
    assert!(top > 0.0);
    for layers in [4usize, 8, 16] {
        let (_, rep) = run(&sc, s.clone(), ov(Some(layers)));
        let j = rep.j.as_ref().unwrap();
        let worst = j.data.iter().zip(&jw.data).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0f32, f32::max) / top;
        let depth = whole.grid_dims.iter().max().copied().unwrap();
        eprintln!("slabs of {layers}: worst |streamed - whole| / max {worst:e}; peak working {} B vs whole {} B", rep.sweep.peak_working_bytes, whole.sweep.peak_working_bytes);
        assert!(worst <= 1e-6, "{layers} layers: {worst}");
        assert!(rep.sweep.slabs > whole.sweep.slabs);
        let map = whole.grid_dims.iter().copied().fold(1, usize::max).pow(2);
        assert!(rep.sweep.peak_working_bytes <= super::stream::working_bytes(map, 9, layers), "{layers}");
        assert!(rep.sweep.peak_working_bytes * (depth as u64 + 1) < whole.sweep.peak_working_bytes * (layers as u64 + 1) + 1);
    }
}

/// Exploration (not in CI): a fixture case with settings from the environment.
#[test]
#[ignore]
fn lpm_explore() {
    use crate::solvers::testing::env_u32;
    let name = std::env::var("LPM_CASE").unwrap_or_else(|_| "plume".into());
    let s = LpmSettings {
        grid_resolution: env_u32("LPM_GRID", 24),
        directions: env_u32("LPM_DIRS", 25),
        storage_per_face: env_u32("LPM_STORAGE", 2),
        output_resolution: env_u32("LPM_OUT", 24),
        max_orders: env_u32("LPM_ORDERS", 200),
        first_order: if std::env::var("LPM_BOUNDARY").is_ok() { FirstOrder::Boundary } else { FirstOrder::Exact },
        ..Default::default()
    };
    if name == "furnace" {
        let sc = furnace_box(0.6);
        let (grid, rep) = run(&sc, LpmSettings { epsilon: 1e-4, max_orders: 2000, ..s }, Overrides::default());
        eprintln!("furnace S / sigma_s {:.4}, {} orders", mean(&s_over_sigma_s(&grid, &sc.medium, 0.99)), rep.orders);
        return;
    }
    let sc = case(&name);
    let t = std::time::Instant::now();
    let (grid, rep) = run(&sc, s.clone(), Overrides::default());
    let e = errors_against_fixture(&name, &sc, &grid);
    eprintln!("{name} {s:?}: {e}; orders {} grid {:?} {:.2} s", rep.orders, rep.grid_dims, t.elapsed().as_secs_f64());
}
