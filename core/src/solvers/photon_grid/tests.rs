//! photon-grid: physical checks and errors against the shared reference fixtures.

use glam::Vec3;

use super::*;
use crate::medium::{procedural, GridLimits, Medium};
use crate::scene::{Camera, Light};
use crate::solvers::testing::{against_single_scattering, cloud::cloud_scene, env_u32, errors_against_fixture, homogeneous_box, Errors};
use crate::solvers::NoProgress;

/// The fixtures' scenes (pop/tests.rs `case`, which wrote them): a 1 m cube of 16^3 voxels,
/// sigma_t 4, albedo 1, at g 0 / 0.7 / 0.9, and the procedural plume (g 0.9, albedo 0.99), lit
/// by a sun travelling along (0.4, -0.5, -0.75), irradiance 3, 16 x 16 pixels; and the dense
/// cloud (testing/cloud.rs).
fn case(name: &str) -> Scene {
    let (medium, dist, fov) = match name {
        "cube_g0" => (homogeneous_box(16, 1.0 / 16.0, 4.0, 1.0, 0.0), 4.0, 22.0),
        "cube_g07" => (homogeneous_box(16, 1.0 / 16.0, 4.0, 1.0, 0.7), 4.0, 22.0),
        "cube_g09" => (homogeneous_box(16, 1.0 / 16.0, 4.0, 1.0, 0.9), 4.0, 22.0),
        "plume" => {
            let (grid, to_world) = procedural::plume(32, GridLimits::default()).unwrap();
            (Medium::new(grid, to_world, Vec3::splat(8.0), Vec3::splat(0.99), 0.9), 6.0, 25.0)
        }
        "cloud" => return cloud_scene(),
        _ => panic!("unknown case {name}"),
    };
    Scene {
        medium,
        lights: vec![Light::Distant { direction: Vec3::new(0.4, -0.5, -0.75).normalize(), irradiance: Vec3::splat(3.0), half_angle: 0.0 }],
        camera: Camera::look_at(Vec3::new(0.0, -dist, 0.3), Vec3::ZERO, Vec3::Z, fov, 16, 16),
        solver: Default::default(),
    }
}

fn solve(sc: &Scene, s: PhotonGridSettings) -> (SolveOutput, PhotonGridReport) {
    PhotonGrid::new(s).unwrap().solve_detailed(sc, &NoProgress).unwrap()
}

fn against(name: &str, s: PhotonGridSettings) -> (Errors, PhotonGridReport, f64) {
    let sc = case(name);
    let t = std::time::Instant::now();
    let (out, rep) = solve(&sc, s);
    let secs = t.elapsed().as_secs_f64();
    (errors_against_fixture(name, &sc, &out.scattering), rep, secs)
}

fn print(name: &str, what: &str, e: &Errors, rep: &PhotonGridReport, secs: f64) {
    let en = &rep.energy;
    let lost = |v: glam::DVec3| v.element_sum() / en.emitted.element_sum().max(1e-30);
    eprintln!(
        "{name} [{what}]: image {:.4} (x{:.3}) grid {:.4} (x{:.3}) multiple {:.4} (x{:.3}); escaped {:.4} absorbed {:.4} cut {:.5}, {:.1} scatterings/photon, {:.3} switched; {secs:.2} s",
        e.image,
        e.image_ratio,
        e.grid,
        e.grid_ratio,
        e.multiple.unwrap_or(f64::NAN),
        e.multiple_ratio.unwrap_or(f64::NAN),
        lost(en.escaped),
        lost(en.absorbed),
        lost(en.cut),
        en.scatterings as f64 / en.photons.max(1) as f64,
        en.switched as f64 / en.photons.max(1) as f64,
    );
}

/// Prints errors for settings variants (PG_CASE selects cases, PG_PHOTONS the photon count).
#[test]
#[ignore]
fn explore() {
    let photons = env_u32("PG_PHOTONS", 1 << 18);
    let only = std::env::var("PG_CASE").unwrap_or_default();
    for name in ["cube_g0", "cube_g07", "cube_g09", "plume", "cloud"] {
        if !only.is_empty() && !name.contains(only.as_str()) {
            continue;
        }
        for (what, s) in [
            ("exact sqrt", PhotonGridSettings { photons, ..Default::default() }),
            ("photons sqrt", PhotonGridSettings { photons, single_scattering: SingleScattering::Photons, ..Default::default() }),
            ("exact linear", PhotonGridSettings { photons, similarity: Similarity::Linear, ..Default::default() }),
            ("exact off", PhotonGridSettings { photons, similarity: Similarity::Off, ..Default::default() }),
        ] {
            let (e, rep, secs) = against(name, s);
            print(name, what, &e, &rep, secs);
        }
    }
}
