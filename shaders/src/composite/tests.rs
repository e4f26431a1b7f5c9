use super::*;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use volscatter_core::compositor;
use volscatter_core::image::relative_rmse;

/// The WGSL validates with naga (no GPU needed) and its `Params` has the Rust struct's size.
#[test]
fn wgsl_validates_and_params_layout_matches() {
    let size = naga_struct_size(WGSL, "Params");
    assert_eq!(size as usize, size_of::<CompositeParams>());
}

/// GPU vs CPU compositor on the default scene (small) with a synthetic S grid: same march,
/// float32 on both sides, same step positions and order; differences come from the exp
/// implementations only. Measured on lavapipe: 1.8e-7 relative RMSE. Tolerance 1e-5 (50x), and
/// 1e-5 absolute on alpha.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_composite_matches_cpu() {
    let ctx = gpu_or_skip();
    let mut scene = Scene::default_scene();
    let c = scene.camera.clone();
    scene.camera = volscatter_core::scene::Camera::look_at(c.position, c.position + c.forward, c.up, c.fov_deg, 48, 40);
    let mut s = ScatteringGrid::over_medium(&scene.medium, 24).unwrap();
    for (i, v) in s.data.iter_mut().enumerate() {
        *v = Vec3::new((i % 7) as f32, (i % 5) as f32, (i % 3) as f32) * 0.1;
    }
    for transparent in [false, true] {
        let opts = CompositeOptions { transparent, ..Default::default() };
        let cpu = compositor::composite(&scene, &s, &opts).unwrap();
        let gpu = composite(&ctx, &scene, &s, &opts).unwrap();
        let a: Vec<Vec3> = gpu.rgba.iter().map(|p| p.truncate()).collect();
        let b: Vec<Vec3> = cpu.rgba.iter().map(|p| p.truncate()).collect();
        let e = relative_rmse(&a, &b);
        eprintln!("transparent={transparent}: rgb relative RMSE {e:e}");
        assert!(e < 1e-5, "transparent={transparent}: rgb relative RMSE {e}");
        let e1 = relative_rmse(gpu.aov("single").unwrap(), cpu.aov("single").unwrap());
        assert!(e1 < 1e-5, "single AOV relative RMSE {e1}");
        let da = gpu.rgba.iter().zip(&cpu.rgba).map(|(p, q)| (p.w - q.w).abs()).fold(0.0f32, f32::max);
        assert!(da < 1e-5, "max alpha difference {da}");
    }
}

#[test]
fn single_wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(single::WGSL, "Params") as usize, size_of::<single::SingleParams>());
    assert_eq!(naga_struct_size(single::WGSL, "Light") as usize, size_of::<single::GpuLight>());
}

/// The single-scattering grid on the GPU against the CPU's: default scene (sun + 64 dome
/// directions), a point light inside the plume, a spot and a disc light. Same march positions and light order;
/// float32 sums of up to 512 samples differ only in exp/sqrt rounding. Tolerance 1e-5.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_single_scattering_grid_matches_cpu() {
    let ctx = gpu_or_skip();
    let mut scene = Scene::default_scene();
    let check = |scene: &Scene, what: &str| {
        let cpu = volscatter_core::stages::single_scattering::single_scattering_grid(scene, 24, 64).unwrap();
        let gpu = single::single_scattering_grid(&ctx, scene, 24, 64).unwrap();
        assert_eq!(cpu.dims, gpu.dims);
        let e = relative_rmse(&gpu.data, &cpu.data);
        eprintln!("{what}: single-scattering grid relative RMSE {e:e}");
        assert!(e < 1e-5, "{what}: {e}");
        assert!(cpu.data.iter().any(|v| v.x > 0.0));
    };
    check(&scene, "sun + dome");
    scene.lights = vec![volscatter_core::scene::Light::Point { position: Vec3::new(0.1, -0.2, 0.0), intensity: Vec3::new(3.0, 2.0, 1.0), radius: 0.0, interior: Default::default() }];
    check(&scene, "point light");
    // Sphere lamps inside the medium, both interiors (docs/scene-format.md "Sphere lamps").
    for interior in [volscatter_core::scene::SphereInterior::Dark, volscatter_core::scene::SphereInterior::Lit] {
        scene.lights = vec![volscatter_core::scene::Light::Point { position: Vec3::new(0.1, -0.2, 0.0), intensity: Vec3::new(3.0, 2.0, 1.0), radius: 0.3, interior }];
        check(&scene, &format!("sphere lamp, {interior:?} interior"));
    }
    // A spot with a blended cone and a disc light (8x8 VPLs with the cosine profile).
    use volscatter_core::scene::{AreaLight, AreaShape, Light, Spot};
    scene.lights = vec![
        Light::Spot(Spot { position: Vec3::new(-1.0, -1.0, 1.0), axis: Vec3::new(1.0, 1.0, -1.0).normalize(), intensity: Vec3::new(3.0, 2.0, 1.0), radius: 0.0, cos_outer: 0.9, cos_inner: 0.95 }),
        Light::Area(AreaLight { center: Vec3::new(1.2, 0.0, 0.0), normal: -Vec3::X, tangent: Vec3::Y, shape: AreaShape::Disk { radius: 0.4 }, radiance: Vec3::ONE }),
    ];
    check(&scene, "spot + disc");
}

/// The bricked density upload (upload.rs, wgsl/density.wgsl) on what the plume lacks: constant tiles
/// (VDB tiles), empty bricks inside the table, negative indices. The single-scattering grid
/// reads the density everywhere along its shadow rays; tolerance as above (1e-5).
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_bricked_density_matches_cpu() {
    use glam::{Affine3A, IVec3};
    use volscatter_core::medium::{DensityGridBuilder, GridLimits, Medium};
    let ctx = gpu_or_skip();
    let mut b = DensityGridBuilder::new(GridLimits::default());
    b.fill_tile(IVec3::new(-16, -8, -8), 8, 0.7).unwrap();
    // x in [-8, 8) stays empty but inside the table, apart from the voxels set below.
    b.fill_tile(IVec3::new(8, -8, -8), 8, 0.3).unwrap();
    for i in 0..40 {
        b.set(IVec3::new(-6 + i % 5, i / 5 - 5, i % 7 - 4), 0.05 * i as f32).unwrap();
    }
    let grid = b.build().unwrap();
    let (_, _, _, bricks, constants) = grid.storage();
    assert!(!bricks.is_empty() && !constants.is_empty(), "the grid should hold both bricks and tiles");
    let mut scene = Scene::default_scene();
    let g = scene.medium.g;
    scene.medium = Medium::new(grid, Affine3A::from_scale(Vec3::splat(0.06)), Vec3::splat(8.0), Vec3::splat(0.9), g);
    let cpu = volscatter_core::stages::single_scattering::single_scattering_grid(&scene, 24, 16).unwrap();
    let gpu = single::single_scattering_grid(&ctx, &scene, 24, 16).unwrap();
    assert_eq!(cpu.dims, gpu.dims);
    let e = relative_rmse(&gpu.data, &cpu.data);
    eprintln!("bricked density: single-scattering grid relative RMSE {e:e}");
    assert!(e < 1e-5, "{e}");
    assert!(cpu.data.iter().any(|v| v.x > 0.0));
}

/// The emissive plume's VPLs (translate::emission, isotropic emitters with a clamp radius, some
/// on grid points: the 24^3 grid over the 64^3 plume shares no points with it, the 64^3 grid
/// does) in the GPU single-scattering grid against the CPU's. Tolerance 1e-5 as above.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_single_scattering_of_emission_matches_cpu() {
    use volscatter_core::medium::{Emission, EmissionLaw, EmissionTerm};
    let ctx = gpu_or_skip();
    let mut scene = Scene::default_scene();
    scene.lights.clear();
    let m = &scene.medium;
    let term = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Blackbody { temperature: 1500.0, intensity: 1.0, tint: Vec3::ONE });
    scene.medium.emission = Some(Emission { terms: vec![term], vpl_count: 64 });
    for dim in [24, 64] {
        let cpu = volscatter_core::stages::single_scattering::single_scattering_grid(&scene, dim, 64).unwrap();
        let gpu = single::single_scattering_grid(&ctx, &scene, dim, 64).unwrap();
        let e = relative_rmse(&gpu.data, &cpu.data);
        eprintln!("emission VPLs, grid {dim}: single-scattering grid relative RMSE {e:e}");
        assert!(e < 1e-5, "grid {dim}: {e}");
        assert!(cpu.data.iter().any(|v| v.x > 0.0));
    }
}
