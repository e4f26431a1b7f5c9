//! A box-filtered mip pyramid of the density, so that coarse propagation cells read the mean
//! density of the volume they cover instead of a point sample (Sec. 4.2: "the medium
//! parameters need to be sampled from a downscaled version of the volume"). Point samples
//! alias: a 32^3 grid over a 256^3 cloud would see one voxel in 512 and miss thin sheets.
//!
//! Only the levels the solver needs are built: the base level already averages `base` voxels
//! per axis, chosen from the finest footprint that will be asked for, which bounds memory by
//! the solver's resolution rather than the VDB's.

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use crate::medium::trilinear::{trilinear, Lattice};
use crate::medium::Medium;

struct Level {
    dims: IVec3,
    /// Voxels per cell along each axis at this level.
    factor: i32,
    data: Vec<f32>,
}

pub struct MediumMip {
    /// Index-space corner (voxel units) of cell 0 of every level.
    lo: IVec3,
    levels: Vec<Level>,
}

impl Level {
    #[inline]
    fn at(&self, c: IVec3) -> f32 {
        if c.x < 0 || c.y < 0 || c.z < 0 || c.x >= self.dims.x || c.y >= self.dims.y || c.z >= self.dims.z {
            0.0
        } else {
            self.data[(c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize]
        }
    }

    /// Trilinear between cell centres, zero outside (like the density grid itself).
    #[inline]
    fn sample(&self, q: Vec3) -> f32 {
        trilinear(q, self)
    }
}

impl Lattice<f32> for &Level {
    #[inline(always)]
    fn at(&self, c: IVec3) -> f32 {
        Level::at(self, c)
    }
}

/// Largest base level per axis for grids wider than any footprint asks for (a 1024^3 level is
/// 4 GiB; footprint-chosen levels are about twice the solver's resolution, far below).
const MAX_BASE_DIM: i64 = 1024;

impl MediumMip {
    /// The base level by visiting every cell's `base`^3 voxels (cells over empty space are
    /// skipped through `max_in_box`).
    fn sum_cells(medium: &Medium, lo: IVec3, dims: IVec3, base: i32) -> Vec<f32> {
        let grid = &medium.grid;
        let mut data = vec![0.0f32; (dims.x * dims.y * dims.z) as usize];
        let inv = 1.0 / (base * base * base) as f32;
        data.par_chunks_mut((dims.x * dims.y) as usize).enumerate().for_each(|(cz, slab)| {
            for cy in 0..dims.y {
                for cx in 0..dims.x {
                    let o = lo + IVec3::new(cx, cy, cz as i32) * base;
                    let mut s = 0.0;
                    if base == 1 {
                        s = grid.voxel(o);
                    } else if grid.max_in_box(o, o + IVec3::splat(base - 1)) > 0.0 {
                        for z in 0..base {
                            for y in 0..base {
                                for x in 0..base {
                                    s += grid.voxel(o + IVec3::new(x, y, z));
                                }
                            }
                        }
                        s *= inv;
                    }
                    slab[(cx + dims.x * cy) as usize] = s;
                }
            }
        });
        data
    }

    /// The base level for huge cells (`base` > 256, where a cell holds more voxels than the
    /// grid stores): each stored voxel is added to its cell, in i64 so that no index wraps.
    fn sum_bricks(medium: &Medium, lo: IVec3, dims: IVec3, base: i32) -> Vec<f32> {
        use crate::medium::grid::{BrickRef, BRICK};
        let mut data = vec![0.0f64; (dims.x * dims.y * dims.z) as usize];
        let inv = 1.0 / (base as f64).powi(3);
        medium.grid.for_each_brick(|origin, brick| {
            for i in 0..(BRICK * BRICK * BRICK) as usize {
                let v = match brick {
                    BrickRef::Dense(values) => values[i],
                    BrickRef::Constant(c) => c,
                };
                let o = IVec3::new(i as i32 & 7, (i as i32 >> 3) & 7, i as i32 >> 6);
                let c = ((origin + o).as_i64vec3() - lo.as_i64vec3()) / base as i64;
                if v != 0.0 && c.cmpge(glam::I64Vec3::ZERO).all() && c.cmplt(dims.as_i64vec3()).all() {
                    data[(c.x + dims.x as i64 * (c.y + dims.y as i64 * c.z)) as usize] += v as f64 * inv;
                }
            }
        });
        data.into_iter().map(|v| v as f32).collect()
    }

    /// Builds levels from `min_footprint` voxels per sample (the finest the caller will ask
    /// for) up to one cell covering the whole grid.
    pub fn new(medium: &Medium, min_footprint: f32) -> Self {
        let grid = &medium.grid;
        if grid.is_empty() {
            return MediumMip { lo: IVec3::ZERO, levels: vec![Level { dims: IVec3::ONE, factor: 1, data: vec![0.0] }] };
        }
        let (blo, bhi) = grid.bbox();
        // One voxel of trilinear ramp on each side, as Medium::index_bounds (saturating: a
        // voxel at the end of the i32 range loses its ramp, not the process).
        let lo = blo.saturating_sub(IVec3::ONE);
        let hi = bhi.saturating_add(IVec3::ONE);
        // In i64: voxels 2^31 apart overflow an i32 extent (issue 22).
        let extent = hi.as_i64vec3() - lo.as_i64vec3() + glam::I64Vec3::ONE;
        // Base factor: largest power of two not above half the finest footprint, so the
        // finest requested level is still interpolated between two stored ones.
        let mut base = 1i32;
        while (base * 2) as f32 <= 0.5 * min_footprint.max(1.0) && base < 256 {
            base *= 2;
        }
        // A sparse grid far wider than any footprint asks for (two voxels 2^31 apart): coarser
        // cells, so that the base level stays at most MAX_BASE_DIM per axis.
        while extent.max_element() > MAX_BASE_DIM * base as i64 && base < 1 << 30 {
            base *= 2;
        }
        let dims = ((extent + glam::I64Vec3::splat(base as i64 - 1)) / base as i64).as_ivec3();
        let data = if base > 256 { Self::sum_bricks(medium, lo, dims, base) } else { Self::sum_cells(medium, lo, dims, base) };
        let mut levels = vec![Level { dims, factor: base, data }];
        while levels.last().unwrap().dims.max_element() > 1 {
            let prev = levels.last().unwrap();
            let nd = (prev.dims + IVec3::ONE) / 2;
            let mut nd_data = vec![0.0f32; (nd.x * nd.y * nd.z) as usize];
            nd_data.par_chunks_mut((nd.x * nd.y) as usize).enumerate().for_each(|(z, slab)| {
                for y in 0..nd.y {
                    for x in 0..nd.x {
                        let mut s = 0.0;
                        for k in 0..8 {
                            let c = IVec3::new(2 * x + (k & 1), 2 * y + ((k >> 1) & 1), 2 * z as i32 + ((k >> 2) & 1));
                            s += prev.at(c); // outside the data: zero, as the density
                        }
                        slab[(x + nd.x * y) as usize] = s * 0.125;
                    }
                }
            });
            let factor = prev.factor.saturating_mul(2);
            levels.push(Level { dims: nd, factor, data: nd_data });
        }
        MediumMip { lo, levels }
    }

    fn sample_level(&self, l: usize, p_index: Vec3) -> f32 {
        let lev = &self.levels[l];
        let f = lev.factor as f32;
        // Cell c covers voxels [lo + c f, lo + (c+1) f): its centre is lo + c f + (f - 1) / 2.
        let q = (p_index - self.lo.as_vec3() - Vec3::splat(0.5 * (f - 1.0))) / f;
        lev.sample(q)
    }

    /// Index-space corner (voxel units) of cell 0 of every level.
    pub fn origin(&self) -> IVec3 {
        self.lo
    }

    /// The levels, finest first: (cells per axis, voxels per cell per axis, x-fastest values).
    /// For ports of `sample` (volscatter-gpu uploads them once per solve).
    pub fn levels(&self) -> impl Iterator<Item = (IVec3, i32, &[f32])> {
        self.levels.iter().map(|l| (l.dims, l.factor, l.data.as_slice()))
    }

    /// What `sample` reads for a footprint: `None` = the density grid itself, else the two
    /// levels and the weight of the second. It depends on the footprint only, so a kernel
    /// sampling at one footprint can take it as a constant.
    pub fn blend(&self, footprint: f32) -> Option<(usize, usize, f32)> {
        let base = self.levels[0].factor as f32;
        if footprint <= 1.0 && base <= 1.0 {
            return None;
        }
        let lf = (footprint.max(1.0) / base).log2().max(0.0);
        let l0 = (lf.floor() as usize).min(self.levels.len() - 1);
        let l1 = (l0 + 1).min(self.levels.len() - 1);
        let t = (lf - l0 as f32).clamp(0.0, 1.0);
        Some((l0, l1, t))
    }

    /// Mean density around index-space point `p` over a box of about `footprint` voxels per
    /// side: trilinear within and linear between the two nearest levels (like GPU trilinear
    /// mip filtering). Footprints of one voxel or less read the density grid itself.
    pub fn sample(&self, medium: &Medium, p_index: Vec3, footprint: f32) -> f32 {
        let Some((l0, l1, t)) = self.blend(footprint) else {
            return medium.grid.sample(p_index);
        };
        let a = self.sample_level(l0, p_index);
        if t == 0.0 || l1 == l0 {
            return a;
        }
        a * (1.0 - t) + self.sample_level(l1, p_index) * t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::{DensityGridBuilder, GridLimits};
    use glam::Affine3A;

    /// Two voxels 2^20 apart (issue 22: 2^31 apart overflowed the i32 extent and panicked):
    /// the base level is coarsened to at most MAX_BASE_DIM + 1 cells per axis instead of 2^20,
    /// built from the stored voxels, and keeps their total density (2 voxels of 1) to 1e-4
    /// (f32 cell means of f64 sums).
    #[test]
    fn voxels_far_apart_give_a_bounded_mip_that_keeps_the_mass() {
        let mut b = DensityGridBuilder::new(GridLimits::default());
        b.set(IVec3::ZERO, 1.0).unwrap();
        b.set(IVec3::new(1 << 20, 0, 0), 1.0).unwrap();
        let medium = Medium::new(b.build().unwrap(), Affine3A::IDENTITY, glam::Vec3::ONE, glam::Vec3::ONE, 0.0);
        let mip = MediumMip::new(&medium, 1.0);
        let (dims, factor, data) = mip.levels().next().unwrap();
        assert!(dims.max_element() as i64 <= MAX_BASE_DIM + 1, "base level {dims}");
        let mass: f64 = data.iter().map(|&v| v as f64).sum::<f64>() * (factor as f64).powi(3);
        assert!((mass - 2.0).abs() < 1e-4, "mass {mass} (factor {factor})");
        assert!(mip.levels().last().unwrap().0.max_element() == 1);
    }
}
