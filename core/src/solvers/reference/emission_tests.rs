//! Physical checks of the reference path tracer with an emitting medium.

use crate::solvers::testing::homogeneous_box;
use super::*;
use crate::medium::{Emission, EmissionLaw, EmissionTerm, Medium};
use crate::scene::Camera;
use crate::stages::{NoProgress, ScatteringGrid};

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

/// The camera sees the emission itself, as Cycles does, in the RGBA and the `emission` AOV,
/// and the compositor marches the same integral: on a purely absorbing emitting box (nothing
/// scatters) the centre pixel is e / sigma_t (1 - exp(-sigma_t l)) along its chord l, in both.
/// The box is 16 voxels of 0.1 and density and emission ramp together at its edges, so the
/// closed form holds exactly with l the chord's optical length over sigma_t, 1.6, on the
/// central 6 x 6 pixels (their rays cross the box from face to face). Tolerance 3% on their
/// mean: 256 paths a pixel give the path tracer ~0.7% noise there; the compositor's march is
/// deterministic, to 1% (its step, half a voxel).
#[test]
fn camera_sees_emission_directly() {
    let r = Reference::new(ReferenceSettings { spp: 256, ..Default::default() }).unwrap();
    let (sigma_t, e) = (1.0f32, 10.0f32);
    let black = scene_of(emitting(homogeneous_box(16, 0.1, sigma_t, 0.0, 0.0), Vec3::splat(e)), 16);
    let img = r.render_image(&black, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    let centre = 8 * 16 + 8;
    let central = |v: &dyn Fn(usize) -> f32| (5..11).flat_map(|y| (5..11).map(move |x| y * 16 + x)).map(v).sum::<f32>() / 36.0;
    let closed = e / sigma_t * (1.0 - (-sigma_t * 1.6f32).exp());
    let traced = central(&|i| img.rgba[i].x);
    assert!((traced - closed).abs() < 0.03 * closed, "path traced {traced} vs closed form {closed}");
    assert_eq!(img.aov("emission").unwrap()[centre], img.rgba[centre].truncate(), "nothing scatters: the image is the emission");
    let zero = ScatteringGrid::over_medium(&black.medium, 16).unwrap();
    let opts = crate::compositor::CompositeOptions { transparent: true, ..Default::default() };
    let comp = crate::compositor::composite(&black, &zero, &opts).unwrap();
    let marched = central(&|i| comp.rgba[i].x);
    assert!((marched - closed).abs() < 0.01 * closed, "composited {marched} vs closed form {closed}");
    assert_eq!(comp.aov("emission").unwrap()[centre], comp.rgba[centre].truncate(), "nothing scatters: the image is the emission");
    assert!(comp.aov("multiple").unwrap()[centre].x.abs() < 1e-4, "emission is not counted as scattering");
    // With scattering, the single-scattering AOV holds light besides.
    let lit = scene_of(emitting(homogeneous_box(16, 0.1, 5.0, 0.8, 0.0), Vec3::splat(10.0)), 16);
    let img = r.render_image(&lit, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    assert!(img.aov("single").unwrap()[centre].x > 0.1);
}

