//! Physical checks of the reference path tracer with an emitting medium.

use crate::solvers::testing::homogeneous_box;
use super::*;
use crate::medium::{Emission, EmissionLaw, EmissionTerm, Medium};
use crate::scene::Camera;
use crate::stages::NoProgress;

/// `medium` emitting `e` (W/m^3/sr) per unit of its own density grid.
fn emitting(mut medium: Medium, e: Vec3) -> Medium {
    let term = EmissionTerm::new(medium.grid.clone(), medium.index_to_world, EmissionLaw::Linear { color: e });
    medium.emission = Some(Emission { terms: vec![term], vpl_count: 64 });
    medium
}

fn scene_of(medium: Medium, size: u32) -> Scene {
    Scene { medium, lights: vec![], camera: Camera::look_at(Vec3::new(0.0, -5.0, 0.0), Vec3::ZERO, Vec3::Z, 30.0, size, size), solver: Default::default() }
}

/// Mean and standard error of `n` one-sample estimates of the in-scattered radiance at `x`.
fn in_scattered_stats(scene: &Scene, x: Vec3, n: u32) -> (f64, f64) {
    let tracer = Tracer::new(scene, &ReferenceSettings::default());
    let mut rng = Rng::new(5, 9);
    let (mut s, mut s2) = (0f64, 0f64);
    for _ in 0..n {
        let v = tracer.in_scattered(x, Vec3::Y, &mut rng).x as f64;
        s += v;
        s2 += v * v;
    }
    let mean = s / n as f64;
    (mean, ((s2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt())
}

/// Kirchhoff's equilibrium, the emission counterpart of the white furnace: deep inside a
/// thick homogeneous medium emitting e uniformly, the radiance is isotropic and uniform, and
/// the RTE 0 = -sigma_t L + sigma_s L + e gives L = e / sigma_a, so the in-scattered radiance
/// (integral of p L) at the centre is e / ((1 - albedo) sigma_t), whatever g. This checks the
/// emission estimator and its transport through many scattering orders together. The box's
/// half-width is 8 optical depths and over 8 diffusion lengths, so leakage is < 1e-3.
/// Tolerance: 4 standard errors + 0.2%.
#[test]
fn emission_absorption_equilibrium() {
    let (sigma_t, e) = (4.0f32, 3.0f32);
    for (albedo, g) in [(0.0f32, 0.0f32), (0.6, 0.0), (0.6, 0.7)] {
        let scene = scene_of(emitting(homogeneous_box(40, 0.1, sigma_t, albedo, g), Vec3::splat(e)), 4);
        let (mean, se) = in_scattered_stats(&scene, Vec3::ZERO, 40_000);
        let expected = (e / ((1.0 - albedo) * sigma_t)) as f64;
        eprintln!("albedo {albedo} g {g}: {mean:.4} vs {expected:.4} (se {se:.4})");
        assert!((mean - expected).abs() < 4.0 * se + 2e-3 * expected, "albedo {albedo} g {g}: {mean} vs {expected} (se {se})");
    }
}

/// An optically thin emitting box (optical depth 0.02 across): the radiance arriving at the
/// centre from direction w is e * l(w), l the distance to the box's surface, so the
/// in-scattered radiance is e times the mean of l over the sphere of directions (computed here
/// by quadrature), and S = sigma_s e <l> (for a sphere of radius R: sigma_s e R). Tolerance: 4 standard errors + 2% for the attenuation it neglects.
#[test]
fn thin_emitting_box_matches_mean_chord() {
    let (n, voxel, e) = (20, 0.05f32, 2.0f32);
    let scene = scene_of(emitting(homogeneous_box(n, voxel, 0.02, 1.0, 0.0), Vec3::splat(e)), 4);
    // Trilinear emission: full inside the outermost voxel centres, a one-voxel linear ramp to
    // zero beyond them; half a voxel of ramp counts as the ramp's mean, so the effective cube
    // has half-width n/2 voxels.
    let h = n as f32 * 0.5 * voxel;
    let k = 400;
    let mut mean_l = 0.0f64;
    for i in 0..k {
        for j in 0..k {
            let w = crate::sampling::uniform_sphere([(i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32]);
            mean_l += (h / w.abs().max_element()) as f64;
        }
    }
    mean_l /= (k * k) as f64;
    let (mean, se) = in_scattered_stats(&scene, Vec3::ZERO, 40_000);
    let expected = e as f64 * mean_l;
    eprintln!("thin box: {mean:.5} vs {expected:.5} (se {se:.5})");
    assert!((mean - expected).abs() < 4.0 * se + 0.02 * expected, "{mean} vs {expected} (se {se})");
}

/// The camera does not see the emission itself (the host renders it): a purely absorbing
/// emitting medium scatters nothing, so the path-traced image and its AOVs are black; with
/// scattering the single-scattering AOV holds light.
#[test]
fn camera_does_not_see_emission_directly() {
    let r = Reference::new(ReferenceSettings { spp: 8, ..Default::default() }).unwrap();
    let black = scene_of(emitting(homogeneous_box(8, 0.1, 5.0, 0.0, 0.0), Vec3::splat(10.0)), 8);
    let img = r.render_image(&black, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    assert!(img.rgba.iter().all(|p| p.truncate() == Vec3::ZERO));
    assert!(img.rgba[4 * 8 + 4].w > 0.9);
    let lit = scene_of(emitting(homogeneous_box(8, 0.1, 5.0, 0.8, 0.0), Vec3::splat(10.0)), 8);
    let img = r.render_image(&lit, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    assert!(img.aov("single").unwrap()[4 * 8 + 4].x > 0.1);
}
