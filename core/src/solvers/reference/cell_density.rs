//! The density the reference's coarse scattering grid multiplies L by: at each grid point, the
//! medium's voxels averaged with the grid's own trilinear (hat) weights, not the density
//! point-sampled there.
//!
//! Why: a host renders S by trilinear interpolation between the grid points, as emission next
//! to the medium's own extinction. With S = sigma_s(point) x L, a grid coarser than the voxels
//! emits what sigma_s happens to be at its points: on Blender's noise cube (40^3 voxels, sun)
//! the 16-cell grid composited to 0.765 of the path-traced flux, on the plume at 12 cells to
//! 1.116. With the hat-averaged density the grid emits, cell by cell, the light that the
//! voxels it covers scatter (the hat functions sum to one: the interpolated S integrates to
//! the integral of sigma_s L with L constant over a cell) — tests.rs
//! `coarse_grid_keeps_the_light` for the measured numbers.

use glam::{IVec3, Vec3};

use crate::medium::Medium;
use crate::solvers::ScatteringGrid;

/// The grid the averaged density lives on: `ScatteringGrid::over_medium` at `max_dim - 2`
/// points per side, padded by one point on every side (at most `max_dim` per side). The padding
/// points sit one cell outside the medium's ramp, where S is zero: a host interpolating the
/// grid's last points down to its zero background over one more cell then renders what the
/// compositor (which stops at the last points) renders, and the first points inside the pad,
/// on the ramp, carry the light of the voxels their cells cover.
pub fn padded_grid(medium: &Medium, max_dim: u32) -> crate::error::Result<ScatteringGrid> {
    let inner = ScatteringGrid::over_medium(medium, max_dim.saturating_sub(2).max(2))?;
    if max_dim < 4 || medium.grid.is_empty() {
        return Ok(inner);
    }
    let dims = [inner.dims[0] + 2, inner.dims[1] + 2, inner.dims[2] + 2];
    let index_to_world = inner.index_to_world * glam::Affine3A::from_translation(Vec3::splat(-1.0));
    Ok(ScatteringGrid { dims, index_to_world, data: vec![Vec3::ZERO; dims.iter().map(|&d| d as usize).product()] })
}

/// Media with more voxels than this (in the grid's span) keep the point-sampled density: the
/// average visits every voxel once (64 M voxels: about a second).
pub const MAX_AVERAGED_VOXELS: i64 = 1 << 26;

/// The hat-weighted average density around every point of `grid` (a grid over `medium`, as
/// `padded_grid` makes), in grid order, zero on its outermost points; None when the medium has more than
/// `MAX_AVERAGED_VOXELS` voxels in the grid's span.
pub fn averaged(medium: &Medium, grid: &ScatteringGrid) -> Option<Vec<f32>> {
    let n = grid.data.len();
    if medium.grid.is_empty() {
        return Some(vec![0.0; n]);
    }
    // The voxels with density: the stored ones plus the one-voxel ramp on each side (zero at
    // its outer end, counted so that a point's weights cover its whole support).
    let (lo, hi) = medium.grid.bbox();
    let (lo, hi) = (lo - IVec3::ONE, hi + IVec3::ONE);
    let extent = (hi - lo + IVec3::ONE).as_i64vec3();
    if extent.x * extent.y * extent.z > MAX_AVERAGED_VOXELS {
        return None;
    }
    let to_grid = grid.index_to_world.inverse() * medium.index_to_world;
    let dims = IVec3::new(grid.dims[0] as i32, grid.dims[1] as i32, grid.dims[2] as i32);
    let mut mass = vec![0.0f64; n];
    let mut weight = vec![0.0f64; n];
    for z in lo.z..=hi.z {
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                let v = IVec3::new(x, y, z);
                let d = medium.grid.voxel(v) as f64;
                let c = to_grid.transform_point3(v.as_vec3());
                let base = c.floor();
                let t = c - base;
                let base = base.as_ivec3();
                for corner in 0..8 {
                    let o = IVec3::new(corner & 1, (corner >> 1) & 1, corner >> 2);
                    let p = base + o;
                    if p.cmplt(IVec3::ZERO).any() || p.cmpge(dims).any() {
                        continue;
                    }
                    let w = Vec3::select(o.cmpeq(IVec3::ONE), t, Vec3::ONE - t);
                    let w = (w.x * w.y * w.z) as f64;
                    let i = grid.index(p.x as u32, p.y as u32, p.z as u32);
                    mass[i] += w * d;
                    weight[i] += w;
                }
            }
        }
    }
    // The outermost points stay at zero (the padding; without it, the ramp's outer end): a
    // host interpolates a VDB's last points down to its zero background over one more cell, the
    // compositor stops at them; any S there would render differently.
    let [nx, ny, nz] = grid.dims;
    let boundary = |i: usize| {
        let (x, y, z) = (i as u32 % nx, (i as u32 / nx) % ny, i as u32 / (nx * ny));
        x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz
    };
    Some(
        mass.iter()
            .zip(&weight)
            .enumerate()
            .map(|(i, (&m, &w))| if w > 0.0 && !boundary(i) { (m / w) as f32 } else { 0.0 })
            .collect(),
    )
}
