//! The sphere-lamp probe, run over every solver that takes point lights: a thin medium around
//! a lamp of radius R, its S at distances inside and outside the sphere against the closed
//! form of docs/scene-format.md ("Sphere lamps"): S = sigma_s I q(d) / 4 pi (g = 0) with q
//! the solid angle of the surface times 1/(pi R^2) outside, and inside nothing (`dark`) or
//! 2/R^2 (`lit`), times the transmittance along the way.

use glam::Vec3;

use super::homogeneous_box;
use crate::scene::{Camera, Light, Scene, SphereInterior};
use crate::solvers::settings_table::LightType;
use crate::solvers::SolveCtx;
use crate::stages::{NoProgress, ScatteringGrid};

const LAMP: f32 = 0.5;
const SIGMA_T: f32 = 0.02;

/// 24^3 voxels of 0.1 m (2.4 m across), optical depth 0.05 across: single scattering is all
/// but ~2% of S.
fn probe_scene(interior: SphereInterior) -> Scene {
    let medium = homogeneous_box(24, 0.1, SIGMA_T, 1.0, 0.0);
    let lamp = Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE, radius: LAMP, interior };
    Scene { medium, lights: vec![lamp], camera: Camera::look_at(Vec3::new(0.0, -6.0, 0.0), Vec3::ZERO, Vec3::Z, 30.0, 16, 16), solver: Default::default() }
}

/// The closed form of S at distance `d` from the lamp's centre.
fn expected(d: f32, interior: SphereInterior) -> f32 {
    let q = crate::medium::lamp_inverse_square(d, LAMP, 0.0, interior == SphereInterior::Lit);
    SIGMA_T * q / (4.0 * std::f32::consts::PI) * (-SIGMA_T * (d - LAMP).max(0.0)).exp()
}

/// Mean of S / closed form (red channel) over the grid points with distance in [lo, hi); for
/// a dark interior, mean S there over the closed form at the surface, just outside.
fn shell_ratio(s: &ScatteringGrid, lo: f32, hi: f32, interior: SphereInterior) -> f64 {
    let (mut sum, mut n) = (0f64, 0u32);
    for k in 0..s.dims[2] {
        for j in 0..s.dims[1] {
            for i in 0..s.dims[0] {
                let p = s.position(i, j, k);
                let d = p.length();
                if d < lo || d >= hi || p.abs().max_element() > 1.0 {
                    continue;
                }
                let e = if d < LAMP && interior == SphereInterior::Dark { expected(LAMP * 1.001, interior) } else { expected(d, interior) };
                sum += (s.data[s.index(i, j, k)].x / e) as f64;
                n += 1;
            }
        }
    }
    assert!(n > 0, "no grid point in [{lo}, {hi})");
    sum / n as f64
}

fn probed_solvers() -> Vec<&'static crate::solvers::settings_table::SolverEntry> {
    crate::solvers::registry::SOLVERS
        .iter()
        .filter(|e| e.name != crate::pipeline::auto::NAME && e.lights.contains(&LightType::Point))
        .collect()
}

/// Bounds, the same for every solver (measured: inside within 0.006 of the model for all six,
/// both interiors; shells 0.3-8% high): ~2-3% of S is multiple scattering, which the closed
/// form leaves out; the near shell is within 1.5 coarse cells of the surface, where a grid's
/// interpolation mixes in the interior (from 2/R^2 at the surface to 0 inside, when dark).
const INSIDE_TOLERANCE: f64 = 0.03;
const NEAR_TOLERANCE: f64 = 0.10;
const FAR_TOLERANCE: f64 = 0.05;

#[test]
fn sphere_lamp_probe_every_solver() {
    let mut failures: Vec<String> = Vec::new();
    for entry in probed_solvers() {
        let solver = entry.build(&entry.test.settings()).unwrap();
        for interior in [SphereInterior::Dark, SphereInterior::Lit] {
            let sc = probe_scene(interior);
            let s = solver.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
            let inside = shell_ratio(&s, 0.0, 0.3, interior);
            let near = shell_ratio(&s, 0.65, 0.8, interior);
            let far = shell_ratio(&s, 0.8, 1.0, interior);
            eprintln!("{:12} {:?}: inside {inside:.3} near {near:.3} far {far:.3}", entry.name, interior);
            let inside_model = if interior == SphereInterior::Lit { 1.0 } else { 0.0 };
            if (inside - inside_model).abs() > INSIDE_TOLERANCE || (near - 1.0).abs() > NEAR_TOLERANCE || (far - 1.0).abs() > FAR_TOLERANCE {
                failures.push(format!("{} {interior:?}: inside {inside:.3} (model {inside_model}), near {near:.3}, far {far:.3}", entry.name));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
