use glam::Vec3;

use super::super::{composite, composite_with_single, single_for, Aovs, CompositeOptions};
use crate::image::relative_rmse;
use crate::scene::{Camera, Light, Scene, SphereInterior, Spot};
use crate::solvers::reference::{Reference, ReferenceSettings};
use crate::solvers::testing::homogeneous_box;
use crate::solvers::{SolveCtx, Solver};
use crate::stages::progress::{NoProgress, Timings};
use crate::stages::ScatteringGrid;

/// A 2 m box of smoke (optical depth 3 across, albedo 0.9, g 0.3) with `lights`, seen from
/// 4 m by a 32 x 24 camera: a pixel is about 9 cm at the box's centre.
fn lamp_scene(lights: Vec<Light>) -> Scene {
    Scene {
        medium: homogeneous_box(16, 0.125, 1.5, 0.9, 0.3),
        lights,
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.3), Vec3::ZERO, Vec3::Z, 40.0, 32, 24),
        solver: Default::default(),
    }
}

/// A spot of radius 0.1 m inside the medium pointing up (the scene set's s12 in small), and a
/// lit sphere lamp of 0.12 m (as the Blender add-on exports a point lamp).
fn lamps_inside() -> Vec<Light> {
    let cos_outer = 35f32.to_radians().cos();
    vec![
        Light::Spot(Spot { position: Vec3::new(-0.3, 0.0, -0.3), axis: Vec3::Z, intensity: Vec3::splat(3.0), radius: 0.1, cos_outer, cos_inner: cos_outer + 0.2 * (1.0 - cos_outer) }),
        Light::Point { position: Vec3::new(0.45, 0.1, 0.25), intensity: Vec3::splat(2.0), radius: 0.12, interior: SphereInterior::Lit },
    ]
}

fn single_aov(scene: &Scene, near_lamps: bool) -> Vec<Vec3> {
    let zero = ScatteringGrid::over_medium(&scene.medium, 16).unwrap();
    let opts = CompositeOptions { aovs: Aovs::parse("single").unwrap(), near_lamps, ..Default::default() };
    composite(scene, &zero, &opts).unwrap().aov("single").unwrap().to_vec()
}

/// Lamps inside the medium: the single-scattering AOV against the path tracer's. The grid's
/// interpolation puts its error in the pixels around each lamp: 0.17 over the image, measured.
/// Near the lamps the composite is within 8% of the path tracer (0.038 measured; the path
/// tracer's AOV at 4096 spp is about 2.5% of it, from 0.105 at 1024 spp) and under 0.4x the
/// grid's error.
#[test]
fn lamps_inside_the_medium_match_the_path_tracer() {
    let scene = lamp_scene(lamps_inside());
    let r = Reference::new(ReferenceSettings { spp: 4096, ..Default::default() }).unwrap();
    let truth = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).unwrap().unwrap();
    let truth = truth.aov("single").unwrap();
    let near = relative_rmse(&single_aov(&scene, true), truth);
    let grid = relative_rmse(&single_aov(&scene, false), truth);
    assert!(near < 0.08, "near lamps: {near} (grid alone {grid})");
    assert!(near < 0.4 * grid, "near lamps {near} against the grid alone {grid}");
}

/// What the pass adds to the scattered light it adds to the `single` AOV, and nothing to the
/// `multiple` one, when S is the single-scattering grid itself (a solver of one order); and with
/// no lamp near the medium (a sun) the image is the grid's march to the bit.
#[test]
fn the_correction_goes_to_the_single_aov_and_only_near_lamps() {
    let scene = lamp_scene(lamps_inside());
    let opts = CompositeOptions { aovs: Aovs::ALL, ..Default::default() };
    let s = single_for(&scene, &opts).unwrap().unwrap();
    let img = composite(&scene, &s, &opts).unwrap();
    let plain = composite_with_single(&scene, &s, Some(&s), &opts).unwrap();
    let moved: f32 = img.rgba.iter().zip(&plain.rgba).map(|(a, b)| (*a - *b).truncate().abs().max_element()).sum();
    assert!(moved > 0.0, "the lamps inside moved no pixel");
    for (m, p) in img.aov("multiple").unwrap().iter().zip(plain.aov("multiple").unwrap()) {
        assert!((*m - *p).abs().max_element() < 1e-4, "multiple moved: {m} vs {p}");
    }
    let sun = lamp_scene(vec![Light::Distant { direction: Vec3::new(0.3, 0.4, -0.8).normalize(), irradiance: Vec3::splat(2.0), half_angle: 0.0 }]);
    let s = single_for(&sun, &opts).unwrap().unwrap();
    assert_eq!(composite(&sun, &s, &opts).unwrap().rgba, composite_with_single(&sun, &s, Some(&s), &opts).unwrap().rgba);
}
