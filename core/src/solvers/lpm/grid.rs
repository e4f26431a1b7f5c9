//! The propagation grid: cubic cells of side h, axis-aligned in the world, over the medium's
//! world bounds, `resolution` cells along the longest side. Each cell holds its mean density
//! (POP's density mip at the cell's footprint, so the extinction is the cell's average, as
//! Eq. 3 assumes constant coefficients per cell) and sigma_t.

use glam::{Affine3A, IVec3, Vec3};

use crate::error::Result;
use crate::medium::Medium;
use crate::stages::mip::MediumMip;
use crate::stages::ScatteringGrid;

pub struct LpmGrid {
    pub dims: [usize; 3],
    /// World corner of cell (0, 0, 0) (its low face).
    pub lo: Vec3,
    pub h: f32,
    /// Grid coordinates of this block's first cell: zero for a whole grid; a slab's box in the
    /// out-of-core solve (out_of_core.rs), whose arrays hold only the box and whose `dims`
    /// are the box's, while `lo` and `h` stay the whole grid's.
    pub offset: [usize; 3],
    pub density: Vec<f32>,
    pub sigma_t: Vec<Vec3>,
}

impl LpmGrid {
    pub fn new(medium: &Medium, resolution: u32, mip: &MediumMip) -> Result<Self> {
        let (dims, lo, h) = Self::geometry(medium, resolution);
        let count = crate::budget::checked_product("lpm propagation grid", &dims.map(|d| d as u64))?;
        // Density and sigma_t (16 bytes a cell) checked together.
        crate::budget::check_elements::<[f32; 4]>("lpm propagation grid (density, sigma_t)", count)?;
        Ok(Self::block(medium, mip, (dims, lo, h), [0; 3], dims))
    }

    /// Dims, world corner and cell side of the grid over `medium` at `resolution` (nothing
    /// allocated: the out-of-core solve builds it block by block).
    pub fn geometry(medium: &Medium, resolution: u32) -> ([usize; 3], Vec3, f32) {
        let (lo, hi) = medium.world_bounds();
        Self::geometry_of_box(lo, hi, resolution)
    }

    /// `geometry` over the world box `lo..hi` (what a medium's `world_bounds` gives): hosts
    /// size the grid from a box before any voxel is read (estimate.rs).
    pub fn geometry_of_box(lo: Vec3, hi: Vec3, resolution: u32) -> ([usize; 3], Vec3, f32) {
        let extent = (hi - lo).max(Vec3::splat(1e-6));
        let h = extent.max_element() / resolution.max(1) as f32;
        let d = (extent / h).ceil().max(Vec3::ONE).as_uvec3();
        ([d.x as usize, d.y as usize, d.z as usize], lo, h)
    }

    /// The cells `offset .. offset + dims` of the grid `geometry`, density and sigma_t sampled
    /// as a whole grid samples them (the same values, cell for cell).
    pub fn block(medium: &Medium, mip: &MediumMip, geometry: ([usize; 3], Vec3, f32), offset: [usize; 3], dims: [usize; 3]) -> Self {
        let (_, lo, h) = geometry;
        let footprint = h / medium.voxel_size_world().max_element();
        let mut density = Vec::with_capacity(dims.iter().product());
        for z in offset[2]..offset[2] + dims[2] {
            for y in offset[1]..offset[1] + dims[1] {
                for x in offset[0]..offset[0] + dims[0] {
                    let c = lo + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * h;
                    density.push(mip.sample(medium, medium.world_to_index.transform_point3(c), footprint).max(0.0));
                }
            }
        }
        let sigma_t = density.iter().map(|&r| medium.sigma_t(r)).collect();
        LpmGrid { dims, lo, h, offset, density, sigma_t }
    }

    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn index(&self, c: [usize; 3]) -> usize {
        let o = self.offset;
        (c[0] - o[0]) + self.dims[0] * ((c[1] - o[1]) + self.dims[1] * (c[2] - o[2]))
    }

    #[inline]
    pub fn centre(&self, c: [usize; 3]) -> Vec3 {
        self.lo + (Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) + 0.5) * self.h
    }

    /// Cell centres as a scattering grid's frame (grid point i at cell i's centre).
    pub fn frame(&self) -> Affine3A {
        Affine3A::from_translation(self.lo + Vec3::splat(0.5 * self.h)) * Affine3A::from_scale(Vec3::splat(self.h))
    }

    /// `data` (one value a cell) as a scattering grid on the cell centres.
    pub fn as_scattering_grid(&self, data: Vec<Vec3>) -> ScatteringGrid {
        ScatteringGrid { dims: self.dims.map(|d| d as u32), index_to_world: self.frame(), data }
    }

    /// Transmittance from world point `x` along unit `w` over at most `t_max`, through the
    /// cells' sigma_t (trilinear between centres, clamped at the faces), midpoint rule with
    /// steps of one cell: the extinction the propagation itself sees.
    pub fn transmittance(&self, x: Vec3, w: Vec3, t_max: f32) -> Vec3 {
        let hi = self.lo + Vec3::new(self.dims[0] as f32, self.dims[1] as f32, self.dims[2] as f32) * self.h;
        let Some((_, t1)) = crate::medium::ray_box(x, w, self.lo, hi) else { return Vec3::ONE };
        let len = t1.min(t_max).max(0.0);
        let steps = (len / self.h).ceil() as u32;
        if steps == 0 {
            return Vec3::ONE;
        }
        let dt = len / steps as f32;
        let d = IVec3::new(self.dims[0] as i32, self.dims[1] as i32, self.dims[2] as i32);
        let top = (d - IVec3::ONE).as_vec3();
        let inv_h = 1.0 / self.h;
        let mut tau = Vec3::ZERO;
        for s in 0..steps {
            let p = x + w * ((s as f32 + 0.5) * dt);
            let q = ((p - self.lo) * inv_h - 0.5).clamp(Vec3::ZERO, top);
            tau += crate::medium::trilinear::dense_inside(q, d, &self.sigma_t);
        }
        (-tau * dt).exp()
    }
}
