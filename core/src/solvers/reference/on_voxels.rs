//! The reference's scattering grid as hosts get it: S = sigma_s(x) * L(x) on the medium's own
//! voxels, with the phase-weighted incident radiance L traced on the coarse `grid_resolution`
//! grid and interpolated (trilinear) to the voxels.
//!
//! Why: a host renders S as emission next to the medium's own extinction, voxel by voxel. S
//! point-sampled on a grid coarser than the voxels blurs sigma_s, the factor that varies
//! fastest, away from where the density is, and loses light (tests.rs
//! `grid_on_voxels_keeps_the_light`). L is smoother than S (sigma_s is known exactly at every
//! voxel): interpolating L and multiplying by the voxel's own sigma_s costs no more paths than
//! the coarse grid. The alternatives measured and dropped: docs/solvers/reference.md.

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use crate::error::Result;
use crate::medium::Medium;
use crate::stages::ScatteringGrid;

/// The output frame (the medium's voxels, up to `output_resolution` per side) and each
/// output point's density.
pub fn output_frame(medium: &Medium, output_resolution: u32) -> Result<(ScatteringGrid, Vec<f32>)> {
    let out = ScatteringGrid::over_medium(medium, output_resolution)?;
    let [nx, ny, _] = out.dims;
    let slab = (nx * ny) as usize;
    let mut density = vec![0.0f32; out.data.len()];
    density.par_chunks_mut(slab.max(1)).enumerate().for_each(|(k, row)| {
        for (idx, d) in row.iter_mut().enumerate() {
            let (i, j) = (idx as u32 % nx, idx as u32 / nx);
            *d = medium.density_world(out.position(i, j, k as u32));
        }
    });
    Ok((out, density))
}

/// Which points of the coarse grid `coarse` are corners of a cell holding an output point
/// with density: the only ones whose L is ever interpolated.
pub fn needed_points(coarse: &ScatteringGrid, out: &ScatteringGrid, density: &[f32]) -> Vec<bool> {
    let to_coarse = coarse.index_to_world.inverse();
    let hi = UVec3::from(coarse.dims) - UVec3::ONE;
    let [nx, ny, _] = out.dims;
    let mut needed = vec![false; coarse.data.len()];
    for (n, &d) in density.iter().enumerate() {
        if d <= 0.0 {
            continue;
        }
        let (i, j, k) = (n as u32 % nx, (n as u32 / nx) % ny, n as u32 / (nx * ny));
        let c = to_coarse.transform_point3(out.position(i, j, k)).max(Vec3::ZERO);
        let lo = c.floor().as_uvec3().min(hi);
        let up = (lo + UVec3::ONE).min(hi);
        for z in [lo.z, up.z] {
            for y in [lo.y, up.y] {
                for x in [lo.x, up.x] {
                    needed[coarse.index(x, y, z)] = true;
                }
            }
        }
    }
    needed
}

/// S on the output frame: each point's sigma_s times L interpolated from `radiance` (the
/// coarse grid of phase-weighted incident radiance).
pub fn scattering(medium: &Medium, radiance: &ScatteringGrid, mut out: ScatteringGrid, density: &[f32]) -> ScatteringGrid {
    let to_coarse = radiance.index_to_world.inverse();
    let [nx, ny, _] = out.dims;
    let frame = out.index_to_world;
    out.data.par_iter_mut().zip(density.par_iter()).enumerate().for_each(|(n, (s, &d))| {
        if d > 0.0 {
            let (i, j, k) = (n as u32 % nx, (n as u32 / nx) % ny, n as u32 / (nx * ny));
            let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
            *s = medium.sigma_s(d) * radiance.sample_index(to_coarse.transform_point3(x));
        }
    });
    out
}
