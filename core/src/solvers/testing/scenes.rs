//! The scenes of the shared reference fixtures (`fixtures/<name>.json`), built once here for
//! every harness (each solver's tests, volscatter-gpu's kernel tests, the cross-language tests):
//! the distant-light cases (`distant_case`: the paper's Fig. 12 cube at three anisotropies and
//! the procedural plume), the local-light cases (`local_light_case`: paper Fig. 10's point light
//! in a sphere, lights beside the plume), the dome cases (`dome_case`) and the dense cloud
//! (cloud.rs). `super::fixture_scene` picks among them by name.

use glam::{Affine3A, IVec3, Vec3};

use super::homogeneous_box;
use crate::medium::{procedural, DensityGrid, GridLimits, Medium};
use crate::scene::light::{AreaLight, AreaShape, Spot};
use crate::scene::{Camera, Environment, LatLongMap, Light, Scene};

/// A homogeneous cube of `n`^3 voxels of density 1 and side 1 m (with its half-voxel ramps),
/// centred at the origin.
pub fn cube(n: i32, sigma_t: f32, albedo: f32, g: f32) -> Medium {
    homogeneous_box(n, 1.0 / n as f32, sigma_t, albedo, g)
}

/// The procedural plume on `n`^3 voxels.
pub fn plume(n: u32, density_scale: f32, albedo: f32, g: f32) -> Medium {
    let (grid, to_world) = procedural::plume(n, GridLimits::default()).unwrap();
    Medium::new(grid, to_world, Vec3::splat(density_scale), Vec3::splat(albedo), g)
}

/// Light travelling down, sideways and towards the camera, so that the camera sees forward,
/// side and back scattering across the medium.
pub const LIGHT_DIR: Vec3 = Vec3::new(0.4, -0.5, -0.75);

/// `medium` lit by a sun along `LIGHT_DIR` (irradiance 3), seen from `cam_dist` in front.
pub fn scene(medium: Medium, size: u32, cam_dist: f32, fov: f32) -> Scene {
    Scene {
        medium,
        lights: vec![Light::Distant { direction: LIGHT_DIR.normalize(), irradiance: Vec3::splat(3.0), half_angle: 0.0 }],
        camera: Camera::look_at(Vec3::new(0.0, -cam_dist, 0.3), Vec3::ZERO, Vec3::Z, fov, size, size),
        solver: Default::default(),
    }
}

/// Image side of the reference fixtures (their grid: `testing::FIXTURE_GRID`).
pub const FIXTURE_SIZE: u32 = 16;

/// The scenes POP is measured on: the paper's Fig. 12 cube (sigma_s = 4 m^-1, albedo 1, side
/// 1 m) at three anisotropies, and the procedural plume with g = 0.9, albedo 0.99.
pub fn distant_case(name: &str) -> Scene {
    let size = FIXTURE_SIZE;
    match name {
        "cube_g0" => scene(cube(16, 4.0, 1.0, 0.0), size, 4.0, 22.0),
        "cube_g07" => scene(cube(16, 4.0, 1.0, 0.7), size, 4.0, 22.0),
        "cube_g09" => scene(cube(16, 4.0, 1.0, 0.9), size, 4.0, 22.0),
        "plume" => scene(plume(32, 8.0, 0.99, 0.9), size, 6.0, 25.0),
        _ => panic!("unknown case {name}"),
    }
}
pub const DISTANT_CASES: [&str; 4] = ["cube_g0", "cube_g07", "cube_g09", "plume"];

/// A uniform sphere of radius `radius` (density 1 inside, antialiased over one voxel) on an
/// `n`^3 grid, centred at the origin, with sigma_s = `sigma_s`, albedo 1.
pub fn sphere(n: i32, radius: f32, sigma_s: Vec3, g: f32) -> Medium {
    let voxel = 2.0 * (radius + 0.1) / n as f32;
    let to_world = Affine3A::from_translation(Vec3::splat(-(n as f32 - 1.0) * 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    let mut vals = vec![0.0f32; (n * n * n) as usize];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = to_world.transform_point3(Vec3::new(x as f32, y as f32, z as f32));
                vals[(x + n * (y + n * z)) as usize] = ((radius - p.length()) / voxel + 0.5).clamp(0.0, 1.0);
            }
        }
    }
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
    Medium::new(grid, to_world, sigma_s, Vec3::ONE, g)
}

/// The local-light cases' plume (32^3, density scale 6, albedo 0.98).
fn local_plume(g: f32) -> Medium {
    plume(32, 6.0, 0.98, g)
}

/// Image side of the local-light fixtures.
pub const LOCAL_SIZE: u32 = 16;

/// The local-light cases: paper Fig. 10 (point light at the centre of a uniform sphere of
/// radius 2.5 m, sigma_s = (0.8, 1, 1.3), albedo 1) at g = 0 and 0.8; a point, a sphere, a spot
/// and a rect light outside the heterogeneous plume (g 0.6).
pub fn local_light_case(name: &str) -> Scene {
    const SIZE: u32 = LOCAL_SIZE;
    let cam = |d: f32, fov: f32| Camera::look_at(Vec3::new(0.0, -d, 0.3), Vec3::ZERO, Vec3::Z, fov, SIZE, SIZE);
    let beside = Vec3::new(1.6, -0.8, 0.6);
    let (medium, light, camera) = match name {
        "fig10_g0" | "fig10_g08" => {
            let g = if name == "fig10_g0" { 0.0 } else { 0.8 };
            // On the axis through the light: the image is symmetric about its centre.
            let camera = Camera::look_at(Vec3::new(0.0, -12.0, 0.0), Vec3::ZERO, Vec3::Z, 28.0, SIZE, SIZE);
            (sphere(32, 2.5, Vec3::new(0.8, 1.0, 1.3), g), Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE, radius: 0.0, interior: Default::default() }, camera)
        }
        "plume_point" => (local_plume(0.6), Light::Point { position: beside, intensity: Vec3::splat(4.0), radius: 0.0, interior: Default::default() }, cam(6.0, 25.0)),
        "plume_sphere" => (local_plume(0.6), Light::Point { position: beside, intensity: Vec3::splat(4.0), radius: 0.4, interior: Default::default() }, cam(6.0, 25.0)),
        "plume_spot" => {
            let axis = (Vec3::new(0.0, 0.0, 0.1) - beside).normalize();
            let spot = Spot { position: beside, axis, intensity: Vec3::splat(8.0), radius: 0.0, cos_outer: 25f32.to_radians().cos(), cos_inner: 18f32.to_radians().cos() };
            (local_plume(0.6), Light::Spot(spot), cam(6.0, 25.0))
        }
        "plume_rect" => {
            let normal = (Vec3::new(0.0, 0.0, 0.1) - beside).normalize();
            let tangent = crate::scene::light::tangent_for(normal, Some(Vec3::Z));
            let a = AreaLight { center: beside, normal, tangent, shape: AreaShape::Rect { width: 0.8, height: 0.5 }, radiance: Vec3::splat(10.0) };
            (local_plume(0.6), Light::Area(a), cam(6.0, 25.0))
        }
        _ => panic!("unknown case {name}"),
    };
    Scene { medium, lights: vec![light], camera, solver: Default::default() }
}
pub const LOCAL_LIGHT_CASES: [&str; 6] = ["fig10_g0", "fig10_g08", "plume_point", "plume_sphere", "plume_spot", "plume_rect"];

/// Direction towards the sun of `sun_sky` (arriving light comes from there).
const SUN: Vec3 = Vec3::new(0.6, -0.3, 0.75);

/// A lat-long sky made here (no file): a sun of 4 degrees radius and radiance 300 (about 60%
/// of the dome's light), a blue sky brightening towards the horizon, a dim brown ground.
pub fn sun_sky(width: usize, height: usize) -> LatLongMap {
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

/// `medium` under the dome `env`, seen as the plume fixtures are.
pub fn dome_scene(medium: Medium, env: Environment) -> Scene {
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
pub fn dome_case(name: &str) -> Scene {
    match name {
        "dome_uniform" => dome_scene(plume(32, 8.0, 0.99, 0.9), Environment { color: Vec3::new(0.5, 0.7, 1.0), map: None }),
        "dome_sun" => dome_scene(plume(32, 8.0, 0.99, 0.9), Environment { color: Vec3::ONE, map: Some(sun_sky(128, 64)) }),
        "dome_milk" => dome_scene(cube(16, MILK_SIGMA_T, 0.999, MILK_G), Environment { color: Vec3::ONE, map: Some(sun_sky(128, 64)) }),
        _ => panic!("unknown dome case {name}"),
    }
}
pub const MILK_SIGMA_T: f32 = 10.0;
pub const MILK_G: f32 = 0.9;
pub const DOME_CASES: [&str; 3] = ["dome_uniform", "dome_sun", "dome_milk"];
