//! The propagation domain of one distant light (Sec. 4, Fig. 2 top): a rectilinear grid of
//! cubic cells whose third axis is the light's direction of travel `d`, spanning the medium's
//! bounds, with the medium's coefficients prefiltered to the cell size.

use glam::{Affine3A, Mat3A, UVec3, Vec3};
use rayon::prelude::*;

use crate::stages::mip::MediumMip;
use crate::stages::progress::{NoProgress, Progress};
use crate::error::{Error, Result};
use crate::medium::optics::box_corners;
use crate::medium::{trilinear, Medium};
use crate::sampling::orthonormal_basis;

#[derive(Clone)]
pub struct LightGrid {
    /// Cells along (u, v, d); x (u) fastest, d slowest so that a slab is one depth slice.
    pub dims: UVec3,
    /// Cell edge, metres.
    pub h: f32,
    /// Principal direction (direction of travel of the light), unit.
    pub d: Vec3,
    /// Grid index space (cell centres at integers, axes u, v, d) to world.
    pub index_to_world: Affine3A,
    pub world_to_index: Affine3A,
    /// Per cell: scattering and absorption coefficients (1/m, RGB), cell averages.
    pub sigma_s: Vec<Vec3>,
    pub sigma_a: Vec<Vec3>,
}

impl LightGrid {
    pub fn len(&self) -> usize {
        self.sigma_s.len()
    }
    pub fn is_empty(&self) -> bool {
        self.sigma_s.is_empty()
    }
    #[inline]
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        i as usize + self.dims.x as usize * (j as usize + self.dims.y as usize * k as usize)
    }
    pub fn slab(&self) -> usize {
        (self.dims.x * self.dims.y) as usize
    }

    /// Sets up the frame and samples the medium. `resolution` cells along the longest side.
    pub fn new(medium: &Medium, mip: &MediumMip, d: Vec3, resolution: u32) -> Result<Self> {
        Self::with_margin(medium, mip, d, resolution, 0, &NoProgress)
    }

    /// As `new`, stopping with `Error::Cancelled` once `progress` is cancelled: a solve's
    /// grids at high resolutions take a core tenths of a second to fill.
    pub fn new_or_cancel(medium: &Medium, mip: &MediumMip, d: Vec3, resolution: u32, progress: &dyn Progress) -> Result<Self> {
        Self::with_margin(medium, mip, d, resolution, 0, progress)
    }

    /// As `new_or_cancel`, with `margin` extra empty cells on every side (the cell size is
    /// that of `new`).
    pub fn with_margin(medium: &Medium, mip: &MediumMip, d: Vec3, resolution: u32, margin: u32, progress: &dyn Progress) -> Result<Self> {
        let d = d.normalize();
        let (u, v) = orthonormal_basis(d);
        let rot = Mat3A::from_cols(u.into(), v.into(), d.into());
        // Extent of the medium's index-space box in the (u, v, d) frame.
        let (lo, hi) = medium.index_bounds();
        let frame = |w: Vec3| Vec3::new(w.dot(u), w.dot(v), w.dot(d));
        let corners = box_corners(lo, hi, |c| frame(medium.index_to_world.transform_point3(c)));
        let (mut pmin, mut pmax) = corners.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(a, b), &p| (a.min(p), b.max(p)));
        let h = (pmax - pmin).max(Vec3::splat(1e-6)).max_element() / resolution as f32;
        pmin -= Vec3::splat(margin as f32 * h);
        pmax += Vec3::splat(margin as f32 * h);
        let extent = (pmax - pmin).max(Vec3::splat(1e-6));
        let dims = (extent / h).ceil().as_uvec3().max(UVec3::ONE);
        let count = dims.x as u64 * dims.y as u64 * dims.z as u64;
        if count > 1 << 27 {
            return Err(Error::TooLarge(format!("pop propagation grid {}x{}x{}", dims.x, dims.y, dims.z)));
        }
        // Centre the cells on the extent (ceil may add up to one cell per axis).
        let origin = pmin - 0.5 * (dims.as_vec3() * h - extent) + Vec3::splat(0.5 * h);
        // world = rot * (origin + h * index)
        let index_to_world = Affine3A { matrix3: rot * h, translation: rot * glam::Vec3A::from(origin) };
        let world_to_index = index_to_world.inverse();

        // Cell averages of the density: footprint of one cell in medium voxels.
        let voxel = medium.voxel_size_world();
        let footprint = h / voxel.min_element();
        let w2i = medium.world_to_index;
        let slab = (dims.x * dims.y) as usize;
        // The solve's light, propagation and merge grids together: ~96 B a cell (measured
        // peak 11.9 GB at grid_resolution 512, issue 22).
        crate::budget::check(&format!("pop grids of {}x{}x{} cells (solver.grid_resolution)", dims.x, dims.y, dims.z), count.saturating_mul(96))?;
        let mut density = vec![0.0f32; count as usize];
        density.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
            if progress.cancelled() {
                return;
            }
            for j in 0..dims.y {
                for i in 0..dims.x {
                    let w = index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                    out[(i + dims.x * j) as usize] = mip.sample(medium, w2i.transform_point3(w), footprint);
                }
            }
        });
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let sigma_s = density.iter().map(|&r| medium.sigma_s(r)).collect();
        let sigma_a = density.iter().map(|&r| medium.sigma_t(r) - medium.sigma_s(r)).map(|s| s.max(Vec3::ZERO)).collect();
        Ok(LightGrid { dims, h, d, index_to_world, world_to_index, sigma_s, sigma_a })
    }

    /// World position of cell (i, j, k)'s centre.
    #[inline]
    pub fn position(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32))
    }

    /// Trilinear lookup of a per-cell field at a world point; zero outside the grid.
    pub fn sample(&self, field: &[Vec3], w: Vec3) -> Vec3 {
        let p = self.world_to_index.transform_point3(w);
        let dims = self.dims.as_ivec3();
        let edge = (dims - glam::IVec3::ONE).as_vec3();
        if !trilinear::inside(p, Vec3::splat(-0.5), edge + Vec3::splat(0.5)) {
            return Vec3::ZERO;
        }
        // Clamp to the outermost centres: the outer half cells hold the edge value.
        trilinear::dense_inside(p.clamp(Vec3::ZERO, edge), dims, field)
    }
}
