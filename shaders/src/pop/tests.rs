use super::*;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use volscatter_core::image::relative_rmse;
use volscatter_core::solvers::pop::propagate::RunOptions;
use volscatter_core::solvers::pop::{accumulate, init, light_grid::LightGrid};
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::stages::NoProgress;
use volscatter_core::Scene;

#[test]
fn wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(WGSL, "Params") as usize, size_of::<PropagateParams>());
}

/// The GPU propagation against the CPU's on the default plume, lit by its sun, for a fixed
/// number of iterations (residual threshold 0 so both run exactly `max_iterations`).
/// float32 on both sides in the same order per cell; exp/sqrt differ in the last bits and the
/// differences compound over iterations. Measured on lavapipe: see the assertion message.
/// Tolerance 1e-4 relative RMSE on J, 1e-4 relative on the energy figures.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_propagation_matches_cpu() {
    let ctx = gpu_or_skip();
    let scene = Scene::default_scene();
    let medium = &scene.medium;
    let sun = scene.lights.iter().find_map(|l| match l {
        volscatter_core::scene::Light::Distant { direction, irradiance, .. } => Some((*direction, *irradiance)),
        _ => None,
    });
    let (dir, irradiance) = sun.unwrap();
    let mip = MediumMip::new(medium, 1.0);
    let grid = LightGrid::new(medium, &mip, dir, 24).unwrap();
    let mu = accumulate::view_cosines(&grid, scene.camera.position);
    let initial = init::sweep(&grid, irradiance);
    for diffusion in [false, true] {
        let prop = Propagation {
            grid: &grid,
            g: medium.g,
            mu: &mu,
            diffusion_correction: diffusion,
            max_iterations: 24,
            residual_threshold: 0.0,
        };
        let mut j_cpu = vec![Vec3::ZERO; grid.len()];
        let keep = RunOptions { keep_remaining: true, ..Default::default() };
        let cpu = prop.run_with(keep, &initial, medium.g, &mut j_cpu, &NoProgress).unwrap();
        let mut j_gpu = vec![Vec3::ZERO; grid.len()];
        let (gpu, _) = propagate(&ctx, &prop, &initial, medium.g, &mut j_gpu, 8, true).unwrap();
        assert_eq!(cpu.iterations, gpu.iterations);
        let e = relative_rmse(&j_gpu, &j_cpu);
        eprintln!("diffusion={diffusion}: J relative RMSE {e:e}");
        assert!(e < 1e-4, "diffusion={diffusion}: J relative RMSE {e}");
        // The packets handed to the isotropic residuum after these iterations.
        let e = relative_rmse(&gpu.remaining, &cpu.remaining);
        eprintln!("diffusion={diffusion}: remaining packets relative RMSE {e:e}");
        assert!(e < 1e-4, "diffusion={diffusion}: remaining packets relative RMSE {e}");
        for (name, a, b) in [
            ("escaped", gpu.escaped, cpu.escaped),
            ("residual", gpu.residual, cpu.residual),
            ("residual anisotropy", gpu.residual_anisotropy, cpu.residual_anisotropy),
        ] {
            let rel = (Vec3::from(a) - Vec3::from(b)).length() / Vec3::from(b).length().max(1e-20);
            assert!(rel < 1e-4, "{name}: gpu {a:?} cpu {b:?}");
        }
    }
}

#[test]
fn sum_wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(sum::WGSL, "Params") as usize, size_of::<sum::SumParams>());
}

/// The isotropic residuum's propagation (a = 0 in a medium-aligned grid with an empty margin,
/// packets gathered from a light's grid) on the GPU against the CPU, as the GPU backend
/// runs it. Same tolerances as above.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_residuum_propagation_matches_cpu() {
    use volscatter_core::solvers::pop::residuum::Residuum;
    let ctx = gpu_or_skip();
    let scene = Scene::default_scene();
    let medium = &scene.medium;
    let mip = MediumMip::new(medium, 1.0);
    let light = LightGrid::new(medium, &mip, glam::Vec3::new(0.3, -0.4, -0.8).normalize(), 16).unwrap();
    let mut residuum = Residuum::new(medium, &mip, 16, &volscatter_core::stages::progress::NoProgress).unwrap();
    residuum.gather(&light, &init::sweep(&light, Vec3::ONE).packets);
    let grid = &residuum.grid;
    let mu = accumulate::view_cosines(grid, scene.camera.position);
    let initial = init::Initial { direct: vec![Vec3::ZERO; grid.len()], packets: residuum.packets.clone(), entering: Vec3::ZERO, transmitted: Vec3::ZERO, absorbed: Vec3::ZERO };
    let prop = Propagation { grid, g: medium.g, mu: &mu, diffusion_correction: true, max_iterations: 24, residual_threshold: 0.0 };
    let mut j_cpu = vec![Vec3::ZERO; grid.len()];
    let cpu = prop.run(&initial, 0.0, &mut j_cpu, &NoProgress).unwrap();
    let mut j_gpu = vec![Vec3::ZERO; grid.len()];
    let (gpu, _) = propagate(&ctx, &prop, &initial, 0.0, &mut j_gpu, 8, false).unwrap();
    assert_eq!(cpu.iterations, gpu.iterations);
    let e = relative_rmse(&j_gpu, &j_cpu);
    eprintln!("residuum: J relative RMSE {e:e}");
    assert!(e < 1e-4, "residuum: J relative RMSE {e}");
    let rel = (Vec3::from(gpu.escaped) - Vec3::from(cpu.escaped)).length() / Vec3::from(cpu.escaped).length().max(1e-20);
    assert!(rel < 1e-4, "escaped: gpu {:?} cpu {:?}", gpu.escaped, cpu.escaped);
}
