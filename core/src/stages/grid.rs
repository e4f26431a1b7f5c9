//! The scattering grid S every solver returns (DESIGN.md "What a solver returns").

use glam::{Affine3A, IVec3, Vec3};

use crate::error::{Error, Result};
use crate::medium::Medium;

/// Largest scattering grid a solver may allocate (512^3 points, 1.5 GiB of RGB floats).
pub const MAX_SCATTERING_GRID_POINTS: u64 = 1 << 27;

/// How finely a scattering grid is laid over a medium: `max_dim` points along its longest
/// side, and where the medium has fewer voxels than that, up to `points_per_voxel` points a
/// voxel, n with n times the voxels within `max_dim` (on the voxels' lattice refined n times,
/// so that the medium's trilinear density is still exact between the points; the one-voxel
/// ramp around the voxels adds 2n - 1 points: a 32-voxel medium at 64 gets 67). A plain `u32`
/// is `max_dim` with one point a voxel at most.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GridSize {
    pub max_dim: u32,
    pub points_per_voxel: u32,
}

impl GridSize {
    /// The points a voxel over a medium of `voxels` along its longest side: n where n times
    /// them fit in `max_dim`, at most `points_per_voxel`, at least 1.
    fn refinement(self, voxels: u32) -> u32 {
        (self.max_dim.max(2) / voxels.max(1)).clamp(1, self.points_per_voxel.max(1))
    }
}

impl From<u32> for GridSize {
    fn from(max_dim: u32) -> Self {
        GridSize { max_dim, points_per_voxel: 1 }
    }
}

/// A dense RGB grid with its own index-to-world map (voxel centres at integer indices),
/// x fastest. Trilinear between voxel centres, zero outside.
#[derive(Clone, Debug)]
pub struct ScatteringGrid {
    pub dims: [u32; 3],
    pub index_to_world: Affine3A,
    pub data: Vec<Vec3>,
}

impl ScatteringGrid {
    /// An all-zero grid covering the medium's bounds: on the medium's own voxel grid when its
    /// extent fits in `size.max_dim` per axis (on that lattice refined n times, n up to
    /// `size.points_per_voxel`, when n times its voxels fit), else on cells of k x k x k
    /// voxels.
    pub fn over_medium(medium: &Medium, size: impl Into<GridSize>) -> Result<Self> {
        let size = size.into();
        let (lo, hi) = medium.grid.bbox();
        if medium.grid.is_empty() {
            return Ok(ScatteringGrid { dims: [1, 1, 1], index_to_world: medium.index_to_world, data: vec![Vec3::ZERO] });
        }
        // Include the one-voxel trilinear ramp around the stored voxels.
        let lo = lo - IVec3::ONE;
        let hi = hi + IVec3::ONE;
        let extent = (hi - lo + IVec3::ONE).as_vec3();
        // The stored voxels are the extent less its ramp.
        let n = size.refinement(extent.max_element() as u32 - 2) as f32;
        let dims = if n > 1.0 {
            // Points 1 / n apart from lo to hi, (extent - 1) n + 1 of them a side.
            ((extent - Vec3::ONE) * n + Vec3::ONE).round().as_uvec3()
        } else {
            let k = (extent.max_element() / size.max_dim.max(2) as f32).max(1.0);
            (extent / k).ceil().as_uvec3().max(glam::UVec3::splat(2))
        };
        let count = dims.x as u64 * dims.y as u64 * dims.z as u64;
        // Checked before allocating (an allocation failure aborts the host): 2^27 points is
        // 1.5 GiB of RGB, a 512^3 grid, beyond anything a preview needs.
        if count > MAX_SCATTERING_GRID_POINTS {
            return Err(Error::TooLarge(format!(
                "scattering grid {}x{}x{} = {count} points is over the limit of {MAX_SCATTERING_GRID_POINTS}",
                dims.x, dims.y, dims.z
            )));
        }
        crate::budget::check_elements::<Vec3>(&format!("scattering grid of {}x{}x{} points", dims.x, dims.y, dims.z), count)?;
        // Grid point i sits at medium index lo + i * step, spanning [lo, hi] exactly.
        let step = (hi - lo).as_vec3() / (dims.as_vec3() - Vec3::ONE);
        let index_to_world = medium.index_to_world * Affine3A::from_translation(lo.as_vec3()) * Affine3A::from_scale(step);
        Ok(ScatteringGrid { dims: dims.to_array(), index_to_world, data: vec![Vec3::ZERO; count as usize] })
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    #[inline]
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        (i as usize) + self.dims[0] as usize * (j as usize + self.dims[1] as usize * k as usize)
    }

    /// World position of grid point (i, j, k).
    pub fn position(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32))
    }

    /// Trilinear lookup at continuous grid-index coordinates; zero outside [0, dims - 1] (and
    /// for NaN).
    #[inline]
    pub fn sample_index(&self, p: Vec3) -> Vec3 {
        let d = IVec3::new(self.dims[0] as i32, self.dims[1] as i32, self.dims[2] as i32);
        if !crate::medium::trilinear::inside(p, Vec3::ZERO, (d - IVec3::ONE).as_vec3()) {
            return Vec3::ZERO;
        }
        crate::medium::trilinear::dense_inside(p, d, &self.data)
    }
}
