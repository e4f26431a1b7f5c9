use super::*;
use crate::pop::light::GpuLight;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use glam::Vec3;
use volscatter_core::image::relative_rmse;
use volscatter_core::solvers::pop::merge as cpu_merge;
use volscatter_core::Scene;

#[test]
fn wgsl_validates_and_params_layout_matches() {
    assert_eq!(naga_struct_size(WGSL, "Params") as usize, size_of::<MergeParams>());
}

/// Two light grids with the same smooth J on both sides, merged on the GPU and by
/// `merge::merge` at three merged resolutions over the 64^3 plume: 24 (footprint 2.7 voxels:
/// levels 1 and 2 blended), 96 (footprint < 1: the CPU reads the density grid itself, the GPU
/// level 0) and 12 over a mip whose finest level averages 4^3 voxels (levels 0 and 1 blended). Same float32 operations in the same order;
/// the affine transforms sum their terms in another order (dot products vs glam's column sums),
/// which moves sample points by an ulp and the trilinear weights with them. Tolerance 1e-5
/// relative RMSE on J and on the density guide.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn gpu_merge_matches_cpu() {
    let ctx = gpu_or_skip();
    let scene = Scene::default_scene();
    let medium = &scene.medium;
    for (mip_footprint, resolution) in [(1.0, 24), (1.0, 96), (8.0, 12)] {
        let mip = MediumMip::new(medium, mip_footprint);
        let gmip = GpuMip::upload(&ctx, &mip).unwrap();
        let dirs = [Vec3::new(-0.5, 0.6, -0.62).normalize(), Vec3::new(0.2, 0.1, 1.0).normalize()];
        let grids: Vec<LightGrid> = dirs.iter().map(|&d| LightGrid::new(medium, &mip, d, 12).unwrap()).collect();
        let js: Vec<Vec<Vec3>> = grids
            .iter()
            .map(|g| (0..g.len()).map(|c| Vec3::new((c % 7) as f32, 1.0 + (c % 5) as f32, (c as f32 * 0.01).sin().abs())).collect())
            .collect();
        let cpu_views: Vec<(&LightGrid, &[Vec3])> = grids.iter().zip(&js).map(|(g, j)| (g, j.as_slice())).collect();
        let cpu = cpu_merge::merge(medium, &mip, &cpu_views, resolution).unwrap();
        let lights: Vec<GpuLight> = grids
            .iter()
            .zip(&js)
            .map(|(g, j)| {
                let l = GpuLight::upload(&ctx, g, &vec![0.0; g.len()]).unwrap();
                ctx.queue.write_buffer(&l.j, 0, bytemuck::cast_slice(&rgb_as_vec4(j)));
                l
            })
            .collect();
        let views: Vec<(&LightGrid, &wgpu::Buffer)> = grids.iter().zip(&lights).map(|(g, l)| (g, &*l.j)).collect();
        let gpu = merge(&ctx, &gmip, medium, &mip, &views, resolution).unwrap().read(&ctx).unwrap();
        assert_eq!(gpu.j.dims, cpu.j.dims);
        let e_j = relative_rmse(&gpu.j.data, &cpu.j.data);
        let dens = |d: &[f32]| d.iter().map(|&v| Vec3::splat(v)).collect::<Vec<_>>();
        let e_d = relative_rmse(&dens(&gpu.density), &dens(&cpu.density));
        eprintln!("merge (mip footprint {mip_footprint}, {resolution}): J relative RMSE {e_j:e}, density {e_d:e}");
        assert!(e_j < 1e-5 && e_d < 1e-5, "J {e_j}, density {e_d}");
        assert!(cpu.j.data.iter().any(|v| v.x > 0.0) && cpu.density.iter().any(|&d| d > 0.0), "nothing compared");
    }
}
