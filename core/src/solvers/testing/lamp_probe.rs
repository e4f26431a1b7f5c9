//! The sphere-lamp probe, run over every solver that takes point lights: a thin medium around
//! a lamp of radius R, its S at distances inside and outside the sphere against the closed
//! form of docs/scene-format.md ("Sphere lamps"): S = sigma_s I q(d) / 4 pi (g = 0) with q
//! the solid angle of the surface times 1/(pi R^2) outside, and inside nothing (`dark`) or
//! 2/R^2 (`lit`), times the transmittance from the lamp's surface.

use glam::Vec3;

use super::homogeneous_box;
use crate::scene::{Camera, Light, Scene, SphereInterior};
use crate::solvers::settings_table::LightType;
use crate::solvers::SolveCtx;
use crate::stages::{NoProgress, ScatteringGrid};

const LAMP: f32 = 0.5;
const SIGMA_T: f32 = 1.0;
const ALBEDO: f32 = 0.05;

/// 24^3 voxels of 0.1 m (2.4 m across), optical depth 2.4 across, so that where the light is
/// attenuated from (the lamp's surface, not its centre: exp(-0.5) apart) shows; albedo 0.05,
/// so that single scattering is all but a few % of S.
fn probe_scene(interior: SphereInterior) -> Scene {
    let medium = homogeneous_box(24, 0.1, SIGMA_T, ALBEDO, 0.0);
    let lamp = Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE, radius: LAMP, interior };
    Scene { medium, lights: vec![lamp], camera: Camera::look_at(Vec3::new(0.0, -6.0, 0.0), Vec3::ZERO, Vec3::Z, 30.0, 16, 16), solver: Default::default() }
}

/// The closed form of S at distance `d` from the lamp's centre in the homogeneous medium: the
/// surface's radiance over the directions that see it, each attenuated over its own path to
/// the surface (a 4096-point midpoint rule in the cosine about the centre's direction).
fn expected(d: f32, interior: SphereInterior) -> f64 {
    let (r, s) = (LAMP as f64, SIGMA_T as f64);
    let d = d as f64;
    let n = 4096;
    // Outside: the cone, its near surface at b - sqrt(b^2 - d^2 + r^2); inside (lit: half the
    // radiance), every direction, to the surface ahead at -b + sqrt(...), b = d mu.
    let (lo, radiance, sign) = if d >= r {
        ((1.0 - r * r / (d * d)).sqrt(), 1.0, -1.0)
    } else if interior == SphereInterior::Lit {
        (-1.0, 0.5, 1.0)
    } else {
        return 0.0;
    };
    let mut sum = 0.0;
    for k in 0..n {
        let mu = lo + (1.0 - lo) * (k as f64 + 0.5) / n as f64;
        let b = d * mu * if sign < 0.0 { 1.0 } else { -1.0 };
        let t = (if sign < 0.0 { b - (b * b - d * d + r * r).max(0.0).sqrt() } else { b + (b * b - d * d + r * r).max(0.0).sqrt() }).max(0.0);
        sum += (-s * t).exp();
    }
    // fluence per W/sr = radiance / (pi r^2) * 2 pi * integral over mu
    let fluence = radiance / (std::f64::consts::PI * r * r) * 2.0 * std::f64::consts::PI * sum * (1.0 - lo) / n as f64;
    ALBEDO as f64 * s * fluence / (4.0 * std::f64::consts::PI)
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
                sum += s.data[s.index(i, j, k)].x as f64 / e;
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

/// Bounds. The reference is exact up to the few % of S that is multiple scattering (which the
/// closed form leaves out): measured 1.6-4.3% high. The solvers take a lamp's light along the
/// direction to its centre from its surface (`PointEmitter::shadow_length`), where it really
/// comes over a cone of longer paths: at this lamp's optical radius (sigma_t r = 0.5) they are
/// 9-18% bright outside it (measured; a KNOWN BIAS, named in docs/scene-format.md, that falls
/// with the lamp's optical size); inside a lit lamp the mean chord in the exponent (Jensen)
/// leaves them within 1.5% (pop within its measured value). Bounds: measured + 3%.
const REFERENCE_TOLERANCE: f64 = 0.06;
const INSIDE_TOLERANCE: f64 = 0.06;
const NEAR_TOLERANCE: f64 = 0.21;
const FAR_TOLERANCE: f64 = 0.21;

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
            let (near_bound, far_bound) = if entry.name == "reference" { (REFERENCE_TOLERANCE, REFERENCE_TOLERANCE) } else { (NEAR_TOLERANCE, FAR_TOLERANCE) };
            // The solvers' bias is one-sided (bright): a dark shell is a different error.
            let (near_low, far_low) = (near < 1.0 - REFERENCE_TOLERANCE, far < 1.0 - REFERENCE_TOLERANCE);
            if (inside - inside_model).abs() > INSIDE_TOLERANCE || near - 1.0 > near_bound || far - 1.0 > far_bound || near_low || far_low {
                failures.push(format!("{} {interior:?}: inside {inside:.3} (model {inside_model}), near {near:.3}, far {far:.3}", entry.name));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
