//! Physical checks of the reference path tracer.

use super::*;
use crate::phase::hg;
use crate::medium::{DensityGrid, GridLimits, Medium};
use crate::scene::{Camera, Environment, Light};
use crate::solvers::NoProgress;
use glam::{Affine3A, IVec3};

/// A homogeneous box of `n`^3 voxels of density 1, voxel size `voxel`, centred at the origin.
pub(crate) fn homogeneous_box(n: i32, voxel: f32, density_scale: f32, albedo: f32, g: f32) -> Medium {
    let vals = vec![1.0f32; (n * n * n) as usize];
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
    let to_world = Affine3A::from_translation(Vec3::splat(-(n as f32 - 1.0) * 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    Medium::new(grid, to_world, Vec3::splat(density_scale), Vec3::splat(albedo), g)
}

fn scene_with(medium: Medium, lights: Vec<Light>, size: u32) -> Scene {
    Scene {
        medium,
        lights,
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.0), Vec3::ZERO, Vec3::Z, 30.0, size, size),
        solver: Default::default(),
    }
}

/// Ratio tracking through a slab: the mean of the estimates is exp(-sigma_t d). The optical
/// depth counts the one-voxel trilinear ramps at each face as half a voxel each, so the
/// effective thickness is n voxels. 4 standard errors of the mean as tolerance.
#[test]
fn slab_transmittance_is_exponential() {
    let n = 8;
    let voxel = 0.1;
    for sigma in [0.5f32, 2.0, 5.0] {
        let scene = scene_with(homogeneous_box(n, voxel, sigma, 0.5, 0.0), vec![], 8);
        let tracer = Tracer::new(&scene, &ReferenceSettings::default());
        let mut rng = Rng::new(11, 0);
        let samples = 100_000;
        let (mut sum, mut sum2) = (0f64, 0f64);
        for _ in 0..samples {
            let t = tracer.transmittance(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, f32::INFINITY, &mut rng).x as f64;
            sum += t;
            sum2 += t * t;
        }
        let mean = sum / samples as f64;
        let se = ((sum2 / samples as f64 - mean * mean).max(0.0) / samples as f64).sqrt();
        let expected = (-(sigma * n as f32 * voxel) as f64).exp();
        assert!((mean - expected).abs() < 4.0 * se + 1e-4, "sigma {sigma}: {mean} vs {expected} (se {se})");
    }
}

/// White furnace: a non-absorbing medium (albedo 1) inside a uniform dome of radiance 1
/// neither adds nor removes energy, so every pixel's expected radiance is exactly 1, however
/// thick the medium and whatever g. The per-image mean must be 1 within 4 standard errors.
#[test]
fn white_furnace_conserves_energy() {
    for g in [0.0f32, 0.8] {
        let medium = homogeneous_box(8, 0.25, 4.0, 1.0, g); // optical thickness 8
        let env = Environment { color: Vec3::ONE, map: None };
        let scene = scene_with(medium, vec![Light::Dome(env)], 16);
        let r = Reference::new(ReferenceSettings { spp: 64, ..Default::default() }).unwrap();
        let img = r.render_image(&scene, &NoProgress, &mut Timings::default()).unwrap();
        let lum: Vec<f64> = img.rgba.iter().map(|p| p.x as f64).collect();
        let mean = lum.iter().sum::<f64>() / lum.len() as f64;
        let var = lum.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (lum.len() - 1) as f64;
        let se = (var / lum.len() as f64).sqrt();
        assert!((mean - 1.0).abs() < 4.0 * se + 1e-3, "g {g}: mean radiance {mean} (se {se})");
        // The medium really was hit: alpha is high in the centre.
        let centre = img.rgba[(8 * 16 + 8) as usize];
        assert!(centre.w > 0.99, "alpha {}", centre.w);
    }
}

/// Under the same white furnace the scattering grid is sigma_s(x) exactly (the phase function
/// integrates to one against uniform radiance 1).
#[test]
fn furnace_scattering_grid_is_sigma_s() {
    let medium = homogeneous_box(6, 0.25, 3.0, 1.0, 0.6);
    let scene = scene_with(medium, vec![Light::Dome(Environment { color: Vec3::ONE, map: None })], 8);
    let r = Reference::new(ReferenceSettings { grid_resolution: 8, grid_spp: 64, ..Default::default() }).unwrap();
    let grid = r.scattering_grid(&scene, &NoProgress, &mut Timings::default()).unwrap();
    let mut ratios = Vec::new();
    for k in 0..grid.dims[2] {
        for j in 0..grid.dims[1] {
            for i in 0..grid.dims[0] {
                let x = grid.position(i, j, k);
                let dens = scene.medium.density_world(x);
                if dens > 0.5 {
                    ratios.push(grid.data[grid.index(i, j, k)].x / scene.medium.sigma_s(dens).x);
                }
            }
        }
    }
    let mean = ratios.iter().sum::<f32>() / ratios.len() as f32;
    assert!(ratios.len() > 20);
    assert!((mean - 1.0).abs() < 0.01, "mean S / sigma_s = {mean}");
}

/// Single scattering of a distant light in an optically thin box has a closed form: for a
/// camera ray through the box centre, L = E * p(cos) * sigma_s * L_path (no attenuation to
/// first order). Checks light units and the phase convention together.
#[test]
fn thin_medium_single_scattering_matches_closed_form() {
    let voxel = 0.1;
    let n = 10;
    let sigma = 0.02; // optical depth 0.02: attenuation below 2%.
    let g = 0.5;
    let medium = homogeneous_box(n, voxel, sigma, 1.0, g);
    let e = 3.0;
    let dir = Vec3::new(1.0, 1.0, -1.0).normalize();
    let scene = scene_with(medium, vec![Light::Distant { direction: dir, irradiance: Vec3::splat(e), half_angle: 0.0 }], 9);
    let r = Reference::new(ReferenceSettings { spp: 4096, ..Default::default() }).unwrap();
    let img = r.render_image(&scene, &NoProgress, &mut Timings::default()).unwrap();
    let centre = img.aov("single").unwrap()[4 * 9 + 4].x;
    // Camera ray travels +y; light propagates along dir; scattered into -(camera ray) = -y.
    let cos = dir.dot(-Vec3::Y);
    let expected = e * hg(cos, g) * sigma * (n as f32 * voxel);
    assert!((centre / expected - 1.0).abs() < 0.05, "{centre} vs {expected}");
}

#[test]
fn same_seed_same_image() {
    let scene = Scene::default_scene();
    let mut scene = scene;
    scene.camera = Camera::look_at(scene.camera.position, Vec3::ZERO, Vec3::Z, 39.6, 12, 12);
    let r = Reference::new(ReferenceSettings { spp: 2, ..Default::default() }).unwrap();
    let a = r.render_image(&scene, &NoProgress, &mut Timings::default()).unwrap();
    let b = r.render_image(&scene, &NoProgress, &mut Timings::default()).unwrap();
    assert_eq!(a.rgba, b.rgba);
}
