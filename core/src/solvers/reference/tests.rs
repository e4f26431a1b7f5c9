//! Physical checks of the reference path tracer.

use super::*;
use crate::phase::hg;
use crate::medium::Medium;
use crate::scene::{Camera, Environment, Light};
// Re-exported for the compositor's tests, which import it from here.
pub(crate) use crate::solvers::testing::homogeneous_box;
use crate::solvers::testing::s_over_sigma_s;
use crate::stages::NoProgress;

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
        let img = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
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
    let ratios = s_over_sigma_s(&grid, &scene.medium, 0.5);
    let mean = ratios.iter().sum::<f32>() / ratios.len() as f32;
    assert!(ratios.len() > 20);
    assert!((mean - 1.0).abs() < 0.01, "mean S / sigma_s = {mean}");
}

/// Mean of `n` one-sample estimates of the in-scattered radiance (integral of p * L) at `x`
/// for a viewer along `view`. Starting at a vertex avoids the free-flight lottery of camera
/// rays in thin media, so these checks are tight.
fn in_scattered_mean(scene: &Scene, x: Vec3, view: Vec3, n: u32) -> Vec3 {
    let tracer = Tracer::new(scene, &ReferenceSettings::default());
    let mut rng = Rng::new(21, 3);
    (0..n).map(|_| tracer.in_scattered(x, view, &mut rng)).sum::<Vec3>() / n as f32
}

/// Single scattering of a distant light at the centre of an optically thin box has a closed
/// form: E * p(cos) * T, with T = exp(-sigma_t * distance to the box face along the light).
/// Checks light units and the phase-function convention together. Multiple scattering adds
/// about sigma_s * size = 2% here: tolerance 4%.
#[test]
fn thin_medium_single_scattering_matches_closed_form() {
    let (voxel, n, sigma, g, e) = (0.1, 10, 0.02, 0.5, 3.0);
    let dir = Vec3::new(1.0, 1.0, -1.0).normalize();
    let scene = scene_with(
        homogeneous_box(n, voxel, sigma, 1.0, g),
        vec![Light::Distant { direction: dir, irradiance: Vec3::splat(e), half_angle: 0.0 }],
        9,
    );
    let view = Vec3::Y; // the camera ray's propagation direction
    let got = in_scattered_mean(&scene, Vec3::ZERO, view, 20_000).x;
    // From the centre, the light enters through a face 0.5 m away along the axis: distance
    // 0.5 * sqrt(3) along dir (the half-voxel ramps average out to the nominal face).
    let t = (-sigma * 0.5 * 3f32.sqrt()).exp();
    let expected = e * hg(dir.dot(-view), g) * t;
    assert!((got / expected - 1.0).abs() < 0.04, "{got} vs {expected}");
}

/// A small bright patch in a lat-long environment map, of radiance L over solid angle Omega,
/// lights the medium like a distant light of irradiance L * Omega from that direction. This
/// pins the map's importance sampling, the MIS with phase sampling and the units together.
/// Tolerance 2%: the patch spans ~6 degrees, across which the phase function (g = 0.3,
/// backscatter) varies by well under 1%; Monte Carlo noise is ~0.3%.
#[test]
fn env_patch_matches_equivalent_distant_light() {
    use crate::scene::LatLongMap;
    let (w, h) = (128usize, 64usize);
    let mut pixels = vec![Vec3::ZERO; w * h];
    let (u0, row0) = (96usize, 20usize);
    let radiance = 40.0f32;
    let mut omega = 0.0f32;
    let mut centre = Vec3::ZERO;
    for row in row0..row0 + 2 {
        let v0 = 1.0 - row as f32 / h as f32;
        let v1 = 1.0 - (row + 1) as f32 / h as f32;
        let band = 2.0 * std::f32::consts::PI * ((std::f32::consts::PI * (v0 - 0.5)).sin() - (std::f32::consts::PI * (v1 - 0.5)).sin());
        for x in u0..u0 + 2 {
            pixels[row * w + x] = Vec3::splat(radiance);
            omega += band / w as f32;
            let uv = [(x as f32 + 0.5) / w as f32, 1.0 - (row as f32 + 0.5) / h as f32];
            centre += LatLongMap::uv_to_direction(uv);
        }
    }
    let to_light = centre.normalize();
    let map = LatLongMap::new(w, h, pixels);
    let medium = || homogeneous_box(10, 0.1, 0.05, 1.0, 0.3);
    let env_scene = scene_with(medium(), vec![Light::Dome(Environment { color: Vec3::ONE, map: Some(map) })], 5);
    let sun_scene = scene_with(
        medium(),
        vec![Light::Distant { direction: -to_light, irradiance: Vec3::splat(radiance * omega), half_angle: 0.0 }],
        5,
    );
    let view = Vec3::new(0.2, 1.0, 0.1).normalize();
    let a = in_scattered_mean(&env_scene, Vec3::ZERO, view, 20_000).x;
    let b = in_scattered_mean(&sun_scene, Vec3::ZERO, view, 20_000).x;
    assert!((a / b - 1.0).abs() < 0.02, "env patch {a} vs distant light {b}: ratio {}", a / b);
}

#[test]
fn same_seed_same_image() {
    let scene = Scene::default_scene();
    let mut scene = scene;
    scene.camera = Camera::look_at(scene.camera.position, Vec3::ZERO, Vec3::Z, 39.6, 12, 12);
    let r = Reference::new(ReferenceSettings { spp: 2, ..Default::default() }).unwrap();
    let a = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    let b = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
    assert_eq!(a.rgba, b.rgba);
}


/// A settings block asking for a 1024^3 scattering grid is refused before allocating (it would
/// be 12 GiB: an allocation failure aborts the host process). The medium spans 1024^3 voxels
/// with only its two corner voxels stored (a few MB of brick table), so the test itself never
/// holds what it checks is refused (a dense 1024^3 box took 4 GiB and 100 s here).
#[test]
fn huge_scattering_grid_is_refused_before_allocating() {
    let mut scene = Scene::default_scene();
    let mut b = crate::medium::DensityGridBuilder::new(crate::medium::GridLimits::default());
    b.set(glam::IVec3::ZERO, 1.0).unwrap();
    b.set(glam::IVec3::splat(1023), 1.0).unwrap();
    let to_world = glam::Affine3A::from_scale(glam::Vec3::splat(0.001));
    scene.medium = Medium::new(b.build().unwrap(), to_world, Vec3::ONE, Vec3::splat(0.5), 0.0);
    let r = Reference::new(ReferenceSettings { grid_resolution: 1024, ..Default::default() }).unwrap();
    let e = r.scattering_grid(&scene, &NoProgress, &mut Timings::default()).unwrap_err().to_string();
    assert!(e.contains("over the limit"), "{e}");
}

/// An optically thin box (single scattering dominates: multiple adds ~2%) for the light tests.
fn thin_box_with(lights: Vec<Light>) -> Scene {
    scene_with(homogeneous_box(10, 0.1, 0.02, 1.0, 0.3), lights, 9)
}

fn spot(position: Vec3, axis: Vec3, intensity: f32, half_angle_deg: f32) -> Light {
    let cos_outer = half_angle_deg.to_radians().cos();
    Light::Spot(crate::scene::Spot { position, axis, intensity: Vec3::splat(intensity), radius: 0.0, cos_outer, cos_inner: cos_outer })
}

/// A spot whose cone is the whole sphere is the point light: same estimator, same random
/// numbers, so the same value to the last bit.
#[test]
fn spot_with_full_cone_is_the_point_light() {
    let pos = Vec3::new(0.3, -0.2, 1.5);
    let s = thin_box_with(vec![spot(pos, -Vec3::Z, 2.0, 180.0)]);
    let p = thin_box_with(vec![Light::Point { position: pos, intensity: Vec3::splat(2.0), radius: 0.0, interior: Default::default() }]);
    let x = Vec3::new(0.1, 0.0, -0.1);
    assert_eq!(in_scattered_mean(&s, x, Vec3::Y, 2000), in_scattered_mean(&p, x, Vec3::Y, 2000));
}

/// Inside a spot's cone the medium is lit as by the point light; outside it, only by light
/// scattered from the lit part (a few percent in this thin box). 10-degree cone from 2 m up:
/// radius 0.35 m at the centre; x = 0.45 m off axis is outside.
#[test]
fn spot_cone_masks_single_scattering() {
    let pos = Vec3::new(0.0, 0.0, 2.0);
    let s = thin_box_with(vec![spot(pos, -Vec3::Z, 5.0, 10.0)]);
    let p = thin_box_with(vec![Light::Point { position: pos, intensity: Vec3::splat(5.0), radius: 0.0, interior: Default::default() }]);
    let inside = in_scattered_mean(&s, Vec3::ZERO, Vec3::Y, 20_000).x / in_scattered_mean(&p, Vec3::ZERO, Vec3::Y, 20_000).x;
    // Inside: the same direct light; multiple scattering (~2% of the point light's) is less.
    assert!((inside - 1.0).abs() < 0.03, "inside the cone: spot / point = {inside}");
    let x = Vec3::new(0.45, 0.0, 0.0);
    let outside = in_scattered_mean(&s, x, Vec3::Y, 20_000).x / in_scattered_mean(&p, x, Vec3::Y, 20_000).x;
    assert!(outside < 0.05, "outside the cone: spot / point = {outside}");
}

/// From far away a small area light is a point light of intensity L A cos(theta) (Lambertian)
/// on its front side and dark behind. Disc of radius 5 cm at 3 m: its extent changes 1/d^2 and
/// the cosine by < 0.1%; Monte Carlo noise with 20,000 paths ~0.5%: tolerance 3%.
#[test]
fn small_area_light_is_a_lambertian_point() {
    use crate::scene::{AreaLight, AreaShape};
    let radiance = 100.0;
    let tilt = Vec3::new(0.0, 0.5, -1.0).normalize(); // normal 26.6 degrees off the line to x
    let disk = AreaLight { center: Vec3::new(0.0, 0.0, 3.0), normal: tilt, tangent: Vec3::X, shape: AreaShape::Disk { radius: 0.05 }, radiance: Vec3::splat(radiance) };
    let rect = AreaLight { shape: AreaShape::Rect { width: 0.1, height: 0.05 }, ..disk };
    for a in [disk, rect] {
        let intensity = radiance * a.area() * tilt.dot(-Vec3::Z);
        let lit = thin_box_with(vec![Light::Area(a)]);
        let point = thin_box_with(vec![Light::Point { position: a.center, intensity: Vec3::splat(intensity), radius: 0.0, interior: Default::default() }]);
        let r = in_scattered_mean(&lit, Vec3::ZERO, Vec3::Y, 20_000).x / in_scattered_mean(&point, Vec3::ZERO, Vec3::Y, 20_000).x;
        assert!((r - 1.0).abs() < 0.03, "{:?}: area / point = {r}", a.shape);
        let back = thin_box_with(vec![Light::Area(AreaLight { normal: -tilt, ..a })]);
        let b = in_scattered_mean(&back, Vec3::ZERO, Vec3::Y, 20_000).x / in_scattered_mean(&point, Vec3::ZERO, Vec3::Y, 20_000).x;
        assert!(b < 0.05, "{:?} facing away: {b}", a.shape);
    }
}

/// The grid the solver hands to hosts keeps the light: with `output_resolution` (the presets
/// set it) S is on the medium's voxels, and composited (as a host renders it, S as emission
/// beside the medium's extinction) it gives the path-traced image's flux also when the paths
/// are traced on grids coarser than the plume's 64 voxels (12 cells, the Preview preset's 32).
/// Printed as the control: the point estimate on the path grid (output_resolution 0, what the
/// fixtures store and what hosts got before). Measured (on voxels / point estimate): 12 cells
/// 0.940 / 1.116, 32 cells 0.987 / 1.009. Tolerance 3% at 32 cells: the path-traced flux's own
/// noise at 256 spp is ~0.3%, the rest is L interpolated across the coarse cells.
#[test]
fn grid_on_voxels_keeps_the_light() {
    let mut scene = Scene::default_scene();
    let c = scene.camera.clone();
    scene.camera = Camera::look_at(c.position, c.position + c.forward, c.up, c.fov_deg, 32, 32);
    let opts = crate::compositor::CompositeOptions { transparent: true, aovs: crate::compositor::Aovs::NONE, ..Default::default() };
    let flux = |im: &crate::image::Image| im.rgba.iter().map(|p| p.truncate().dot(Vec3::ONE) as f64).sum::<f64>();
    let mut t = Timings::default();
    let truth = flux(&Reference::new(ReferenceSettings { spp: 256, transparent: true, ..Default::default() }).unwrap()
        .render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut t).expect("the reference renders images")
        .unwrap());
    for grid_resolution in [12, 32] {
        let settings = ReferenceSettings { grid_resolution, grid_spp: 32, transparent: true, output_resolution: 128, ..Default::default() };
        let r = Reference::new(settings.clone()).unwrap();
        let on_voxels = r.solve(&scene, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
        assert!(on_voxels.dims.iter().max().unwrap() > &40, "output not on the voxels: {:?}", on_voxels.dims);
        let ratio = flux(&crate::compositor::composite(&scene, &on_voxels, &opts).unwrap()) / truth;
        let point = Reference::new(ReferenceSettings { output_resolution: 0, ..settings }).unwrap().solve(&scene, &mut SolveCtx::new(&NoProgress)).unwrap().scattering;
        assert!(point.dims.iter().all(|&d| d <= grid_resolution), "output_resolution 0: the path grid {:?}", point.dims);
        let point_ratio = flux(&crate::compositor::composite(&scene, &point, &opts).unwrap()) / truth;
        eprintln!("{grid_resolution} cells: flux over the path-traced image's: on voxels {ratio:.4}, point estimate {point_ratio:.4}");
        if grid_resolution == 32 {
            assert!((ratio - 1.0).abs() < 0.03, "grid on voxels: flux ratio {ratio}");
        }
    }
}
