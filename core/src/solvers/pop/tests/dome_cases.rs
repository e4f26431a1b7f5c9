//! POP under environment lighting (paper 01, Sec. 5) against the reference path tracer, and the
//! isotropic residuum's effect.

use super::*;
use crate::scene::{Environment, LatLongMap};

/// Direction towards the sun of `sun_sky` (arriving light comes from there).
const SUN: Vec3 = Vec3::new(0.6, -0.3, 0.75);

/// A lat-long sky made here (no file): a sun of 4 degrees radius and radiance 300 (about 60%
/// of the dome's light), a blue sky brightening towards the horizon, a dim brown ground.
pub(super) fn sun_sky(width: usize, height: usize) -> LatLongMap {
    let sun = SUN.normalize();
    let cos_sun = 4.0f32.to_radians().cos();
    let pixels = (0..width * height)
        .map(|c| {
            let (x, r) = (c % width, c / width);
            let d = LatLongMap::uv_to_direction([(x as f32 + 0.5) / width as f32, 1.0 - (r as f32 + 0.5) / height as f32]);
            if d.dot(sun) > cos_sun {
                Vec3::splat(300.0)
            } else if d.z >= 0.0 {
                Vec3::new(0.25, 0.45, 1.0) * (0.5 + 0.5 * (1.0 - d.z))
            } else {
                Vec3::new(0.15, 0.12, 0.1)
            }
        })
        .collect();
    LatLongMap::new(width, height, pixels)
}

fn dome_scene(medium: Medium, env: Environment) -> Scene {
    Scene {
        medium,
        lights: vec![Light::Dome(env)],
        camera: Camera::look_at(Vec3::new(0.0, -6.0, 0.3), Vec3::ZERO, Vec3::Z, 25.0, FIXTURE_SIZE, FIXTURE_SIZE),
        solver: Default::default(),
    }
}

/// The dome cases: the heterogeneous plume (g 0.9, albedo 0.99) under a uniform bluish dome
/// and under the sun sky, and a nearly white plume (albedo 0.999) under the sun sky, where
/// light scatters hundreds of times (the isotropic residuum's case).
pub(super) fn dome_case(name: &str) -> Scene {
    match name {
        "dome_uniform" => dome_scene(plume(32, 8.0, 0.99, 0.9), Environment { color: Vec3::new(0.5, 0.7, 1.0), map: None }),
        "dome_sun" => dome_scene(plume(32, 8.0, 0.99, 0.9), Environment { color: Vec3::ONE, map: Some(sun_sky(128, 64)) }),
        "dome_milk" => dome_scene(plume(32, 8.0, 0.999, 0.9), Environment { color: Vec3::ONE, map: Some(sun_sky(128, 64)) }),
        _ => panic!("unknown dome case {name}"),
    }
}
const DOME_CASES: [&str; 3] = ["dome_uniform", "dome_sun", "dome_milk"];

/// Regenerates the dome fixtures (`cargo nextest run -p volscatter-core --cargo-profile release
/// regenerate_dome_fixtures --run-ignored only`; `FIXTURE_SPP`, `FIXTURE_GRID_SPP`, `POP_CASE` as
/// for `regenerate_fixtures`).
#[test]
#[ignore]
fn regenerate_dome_fixtures() {
    let env = |k: &str, d: u32| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let (spp, grid_spp) = (env("FIXTURE_SPP", 16384), env("FIXTURE_GRID_SPP", 4096));
    let only = std::env::var("POP_CASE").unwrap_or_default();
    for name in DOME_CASES.iter().filter(|n| only.is_empty() || n.contains(only.as_str())) {
        regenerate_fixture(name, &dome_case(name), spp, grid_spp);
    }
}

/// Settings of the dome tests: 12-cell ordinate grids, so that 125 ordinates solve in seconds.
fn dome_settings(n: u32) -> PopSettings {
    PopSettings { grid_resolution: 16, dome_grid_resolution: 12, output_resolution: 32, dome_ordinates: n, ..Default::default() }
}

/// Prints errors for the dome cases over N, importance and residuum (`cargo nextest run -p
/// volscatter-core --cargo-profile release explore_domes --run-ignored only --no-capture`).
#[test]
#[ignore]
fn explore_domes() {
    let only = std::env::var("POP_CASE").unwrap_or_default();
    for name in DOME_CASES.iter().filter(|n| only.is_empty() || n.contains(only.as_str())) {
        let sc = dome_case(name);
        for n in [16u32, 64, 125] {
            for (imp, res) in [(true, true), (false, true), (true, false)] {
                let st = PopSettings { dome_importance: imp, isotropic_residuum: res, ..dome_settings(n) };
                let t = std::time::Instant::now();
                let (e, rep) = pop_vs_fixture_scene(name, &sc, &st);
                eprintln!(
                    "{name:12} N {n:3} importance {imp:5} residuum {res:5}: image {:.4} (x{:.3}) grid {:.4} (x{:.3}) multiple {:.4} updates {:>10} balance {:.4} {:.2}s",
                    e.image, e.image_ratio, e.grid, e.grid_ratio, e.multiple, rep.cell_updates(), rep.energy_balance()[0], t.elapsed().as_secs_f64()
                );
            }
        }
    }
}
