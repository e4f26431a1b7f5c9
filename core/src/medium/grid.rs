//! Sparse density grid: 8^3 bricks (the size of an OpenVDB leaf) addressed through a dense table
//! over the bounding box in bricks. Constant bricks (VDB tiles) cost one table entry and no
//! voxel storage, so a large uniform tile stays cheap; empty space costs one table entry.
//!
//! Values live at integer index coordinates (voxel centres), interpolate trilinearly between
//! them and are zero outside the stored voxels — OpenVDB's and Cycles' convention.

use glam::{IVec3, Vec3};
use std::collections::HashMap;

use crate::error::{Error, Result};

pub const BRICK_LOG2: i32 = 3;
pub const BRICK: i32 = 1 << BRICK_LOG2;
pub const BRICK_VOXELS: usize = (BRICK * BRICK * BRICK) as usize;

/// Table entry meaning "all zero".
pub const EMPTY: u32 = 0;
/// Table entries with this bit set index `constants`; otherwise entry - 1 indexes `bricks`.
pub const CONSTANT_BIT: u32 = 1 << 31;

/// Limits checked *before* memory is allocated for a grid.
#[derive(Clone, Copy, Debug)]
pub struct GridLimits {
    /// Bytes of brick storage plus table.
    pub max_bytes: u64,
    /// Voxels covered by the bounding box of the stored data. Solvers' cost grows with the
    /// extent, and a single VDB root tile can cover 4096^3 voxels with a few bytes of file.
    pub max_extent_voxels: u64,
}

impl Default for GridLimits {
    fn default() -> Self {
        // 8 GiB, and 2048^3 voxels: larger than any production cloud we know of at preview time.
        GridLimits { max_bytes: 8 << 30, max_extent_voxels: 1 << 33 }
    }
}

#[derive(Clone, Debug)]
pub struct DensityGrid {
    /// Minimum corner of the table, in bricks.
    brick_min: IVec3,
    /// Table size in bricks.
    brick_dims: IVec3,
    table: Vec<u32>,
    bricks: Vec<[f32; BRICK_VOXELS]>,
    constants: Vec<f32>,
    /// Inclusive index bounding box of the stored voxels (empty grid: min > max).
    bbox_min: IVec3,
    bbox_max: IVec3,
    max_value: f32,
}

#[inline]
fn voxel_offset(local: IVec3) -> usize {
    // x fastest, like the dense buffers of the C ABI.
    (local.x | (local.y << BRICK_LOG2) | (local.z << (2 * BRICK_LOG2))) as usize
}

impl DensityGrid {
    pub fn empty() -> Self {
        DensityGrid {
            brick_min: IVec3::ZERO,
            brick_dims: IVec3::ZERO,
            table: Vec::new(),
            bricks: Vec::new(),
            constants: Vec::new(),
            bbox_min: IVec3::splat(1),
            bbox_max: IVec3::splat(0),
            max_value: 0.0,
        }
    }

    /// Dense x-fastest array of `dims` voxels whose voxel (0,0,0) is at index `origin`.
    pub fn from_dense(origin: IVec3, dims: IVec3, values: &[f32], limits: GridLimits) -> Result<Self> {
        let count = dims.x.max(0) as u64 * dims.y.max(0) as u64 * dims.z.max(0) as u64;
        if values.len() as u64 != count {
            return Err(Error::InvalidArgument(format!(
                "dense grid {}x{}x{} needs {count} values, got {}",
                dims.x, dims.y, dims.z, values.len()
            )));
        }
        let mut b = DensityGridBuilder::new(limits);
        b.reserve_extent(origin, origin + dims - IVec3::ONE)?;
        for z in 0..dims.z {
            for y in 0..dims.y {
                let row = ((z as usize * dims.y as usize) + y as usize) * dims.x as usize;
                for x in 0..dims.x {
                    let v = values[row + x as usize];
                    if v != 0.0 {
                        b.set(origin + IVec3::new(x, y, z), v)?;
                    }
                }
            }
        }
        b.build()
    }

    pub fn is_empty(&self) -> bool {
        self.bbox_min.cmpgt(self.bbox_max).any()
    }
    /// Inclusive index bounding box of the stored voxels.
    pub fn bbox(&self) -> (IVec3, IVec3) {
        (self.bbox_min, self.bbox_max)
    }
    pub fn max_value(&self) -> f32 {
        self.max_value
    }
    /// The sparse storage as it is, for uploads that keep it sparse (volscatter-gpu): corner and
    /// size of the table in bricks, the table (`EMPTY`, `CONSTANT_BIT | i` for `constants[i]`,
    /// else `i + 1` for `bricks[i]`), the bricks (8^3 voxels, x fastest) and the constants.
    pub fn storage(&self) -> (IVec3, IVec3, &[u32], &[[f32; BRICK_VOXELS]], &[f32]) {
        (self.brick_min, self.brick_dims, &self.table, &self.bricks, &self.constants)
    }

    pub fn memory_bytes(&self) -> u64 {
        (self.table.len() * 4 + self.bricks.len() * BRICK_VOXELS * 4 + self.constants.len() * 4) as u64
    }

    /// Value at an integer voxel; zero outside.
    #[inline(always)]
    pub fn voxel(&self, ijk: IVec3) -> f32 {
        let b = (ijk >> BRICK_LOG2) - self.brick_min;
        if b.x < 0 || b.y < 0 || b.z < 0 || b.x >= self.brick_dims.x || b.y >= self.brick_dims.y || b.z >= self.brick_dims.z {
            return 0.0;
        }
        let entry = self.table[(b.x + self.brick_dims.x * (b.y + self.brick_dims.y * b.z)) as usize];
        if entry == EMPTY {
            0.0
        } else if entry & CONSTANT_BIT != 0 {
            self.constants[(entry & !CONSTANT_BIT) as usize]
        } else {
            self.bricks[(entry - 1) as usize][voxel_offset(ijk & (BRICK - 1))]
        }
    }

    /// Trilinear interpolation at continuous index coordinates (voxel centres at integers);
    /// zero outside the stored voxels' ramp and for NaN or huge coordinates.
    #[inline]
    pub fn sample(&self, p: Vec3) -> f32 {
        super::trilinear::trilinear(p, self)
    }

    /// Maximum voxel value over the inclusive index box (used for majorants). Constant and
    /// empty bricks are answered without visiting their voxels.
    pub fn max_in_box(&self, lo: IVec3, hi: IVec3) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let lo = lo.max(self.bbox_min);
        let hi = hi.min(self.bbox_max);
        if lo.cmpgt(hi).any() {
            return 0.0;
        }
        let blo = (lo >> BRICK_LOG2) - self.brick_min;
        let bhi = (hi >> BRICK_LOG2) - self.brick_min;
        let mut m = 0.0f32;
        for bz in blo.z..=bhi.z {
            for by in blo.y..=bhi.y {
                for bx in blo.x..=bhi.x {
                    let entry = self.table[(bx + self.brick_dims.x * (by + self.brick_dims.y * bz)) as usize];
                    if entry == EMPTY {
                        continue;
                    }
                    if entry & CONSTANT_BIT != 0 {
                        m = m.max(self.constants[(entry & !CONSTANT_BIT) as usize]);
                        continue;
                    }
                    let brick = &self.bricks[(entry - 1) as usize];
                    let base = (IVec3::new(bx, by, bz) + self.brick_min) << BRICK_LOG2;
                    let l = (lo - base).max(IVec3::ZERO);
                    let h = (hi - base).min(IVec3::splat(BRICK - 1));
                    for z in l.z..=h.z {
                        for y in l.y..=h.y {
                            for x in l.x..=h.x {
                                m = m.max(brick[voxel_offset(IVec3::new(x, y, z))]);
                            }
                        }
                    }
                }
            }
        }
        m
    }

    /// Visits every stored brick: its minimum voxel (a multiple of 8) and either its 512
    /// values (x fastest) or the constant that fills it. Empty bricks are not visited.
    pub fn for_each_brick(&self, mut f: impl FnMut(IVec3, BrickRef<'_>)) {
        for bz in 0..self.brick_dims.z {
            for by in 0..self.brick_dims.y {
                for bx in 0..self.brick_dims.x {
                    let e = self.table[(bx + self.brick_dims.x * (by + self.brick_dims.y * bz)) as usize];
                    if e == EMPTY {
                        continue;
                    }
                    let origin = (IVec3::new(bx, by, bz) + self.brick_min) << BRICK_LOG2;
                    if e & CONSTANT_BIT != 0 {
                        f(origin, BrickRef::Constant(self.constants[(e & !CONSTANT_BIT) as usize]));
                    } else {
                        f(origin, BrickRef::Dense(&self.bricks[(e - 1) as usize]));
                    }
                }
            }
        }
    }

    /// Sum of all stored voxel values and their count (constant bricks counted by the voxels
    /// they cover). Used by `vdb-info`-style statistics and tests.
    pub fn sum_and_count_nonzero(&self) -> (f64, u64) {
        let mut sum = 0.0f64;
        let mut count = 0u64;
        for &e in &self.table {
            if e == EMPTY {
                continue;
            }
            if e & CONSTANT_BIT != 0 {
                let c = self.constants[(e & !CONSTANT_BIT) as usize];
                sum += c as f64 * BRICK_VOXELS as f64;
                count += BRICK_VOXELS as u64;
            } else {
                for &v in self.bricks[(e - 1) as usize].iter() {
                    if v != 0.0 {
                        sum += v as f64;
                        count += 1;
                    }
                }
            }
        }
        (sum, count)
    }
}

/// One stored brick, as [`DensityGrid::for_each_brick`] sees it.
#[derive(Clone, Copy, Debug)]
pub enum BrickRef<'a> {
    /// 512 values, x fastest (offset `x | y << 3 | z << 6`).
    Dense(&'a [f32; BRICK_VOXELS]),
    /// Every voxel of the brick has this value.
    Constant(f32),
}

/// Collects voxels and constant bricks, checking limits as it goes, then lays out the table.
pub struct DensityGridBuilder {
    limits: GridLimits,
    bricks: HashMap<IVec3, Box<[f32; BRICK_VOXELS]>>,
    constants: HashMap<IVec3, f32>,
    bbox_min: IVec3,
    bbox_max: IVec3,
    clamped_negative: u64,
}

impl DensityGridBuilder {
    pub fn new(limits: GridLimits) -> Self {
        DensityGridBuilder {
            limits,
            bricks: HashMap::new(),
            constants: HashMap::new(),
            bbox_min: IVec3::splat(i32::MAX),
            bbox_max: IVec3::splat(i32::MIN),
            clamped_negative: 0,
        }
    }

    /// Number of negative values that were clamped to zero (reported as a warning by callers;
    /// small negative densities are common in simulation caches).
    pub fn clamped_negative(&self) -> u64 {
        self.clamped_negative
    }

    fn extent_voxels(lo: IVec3, hi: IVec3) -> u64 {
        let d = (hi.as_i64vec3() - lo.as_i64vec3() + glam::I64Vec3::ONE).max(glam::I64Vec3::ZERO);
        (d.x as u64).saturating_mul(d.y as u64).saturating_mul(d.z as u64)
    }

    /// Grows the bounding box to include [lo, hi] after checking the extent limit.
    pub fn reserve_extent(&mut self, lo: IVec3, hi: IVec3) -> Result<()> {
        let nlo = self.bbox_min.min(lo);
        let nhi = self.bbox_max.max(hi);
        let extent = Self::extent_voxels(nlo, nhi);
        if extent > self.limits.max_extent_voxels {
            return Err(Error::TooLarge(format!(
                "density grid would span {} x {} x {} = {extent} voxels, over the limit of {} voxels",
                nhi.x as i64 - nlo.x as i64 + 1,
                nhi.y as i64 - nlo.y as i64 + 1,
                nhi.z as i64 - nlo.z as i64 + 1,
                self.limits.max_extent_voxels
            )));
        }
        // Table entries over the brick bounding box plus the bricks themselves.
        let bricks_extent = Self::extent_voxels(nlo >> BRICK_LOG2, nhi >> BRICK_LOG2);
        let bytes = bricks_extent * 4 + (self.bricks.len() as u64 + 1) * (BRICK_VOXELS as u64 * 4);
        if bytes > self.limits.max_bytes {
            return Err(Error::TooLarge(format!(
                "density grid needs about {} MiB, over the limit of {} MiB",
                bytes >> 20,
                self.limits.max_bytes >> 20
            )));
        }
        self.bbox_min = nlo;
        self.bbox_max = nhi;
        Ok(())
    }

    /// A density value must be finite (the VDB filter checks each voxel with this too).
    pub(crate) fn check_value(v: f32, ijk: IVec3) -> Result<()> {
        if !v.is_finite() {
            return Err(Error::InvalidArgument(format!(
                "density at voxel ({}, {}, {}) is {v}: densities must be finite",
                ijk.x, ijk.y, ijk.z
            )));
        }
        Ok(())
    }

    /// Sets one voxel. Negative values are clamped to zero and counted; NaN/inf is an error.
    pub fn set(&mut self, ijk: IVec3, v: f32) -> Result<()> {
        Self::check_value(v, ijk)?;
        let v = if v < 0.0 {
            self.clamped_negative += 1;
            0.0
        } else {
            v
        };
        let key = ijk >> BRICK_LOG2;
        if !self.bricks.contains_key(&key) {
            if v == 0.0 && !self.constants.contains_key(&key) {
                return Ok(());
            }
            self.reserve_extent(ijk, ijk)?;
            let fill = self.constants.remove(&key).unwrap_or(0.0);
            self.bricks.insert(key, Box::new([fill; BRICK_VOXELS]));
        } else if ijk.cmplt(self.bbox_min).any() || ijk.cmpgt(self.bbox_max).any() {
            self.reserve_extent(ijk, ijk)?;
        }
        self.bricks.get_mut(&key).unwrap()[voxel_offset(ijk & (BRICK - 1))] = v;
        Ok(())
    }

    /// Sets a whole brick at once (the fast path of the VDB reader): `origin` must be a
    /// multiple of 8, `values` are x fastest. Negative values are clamped to zero and counted,
    /// NaN/inf is an error; an all-zero brick stores nothing. The bounding box grows to the
    /// non-zero voxels only, after checking the limits.
    pub fn set_leaf(&mut self, origin: IVec3, values: &[f32; BRICK_VOXELS]) -> Result<()> {
        if (origin & (BRICK - 1)) != IVec3::ZERO {
            return Err(Error::InvalidArgument(format!("brick at {origin} is not brick-aligned")));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let local = IVec3::new(i as i32 & (BRICK - 1), (i as i32 >> BRICK_LOG2) & (BRICK - 1), i as i32 >> (2 * BRICK_LOG2));
            Self::check_value(values[i], origin + local)?;
        }
        let negatives = values.iter().filter(|v| **v < 0.0).count() as u64;
        // Bounding box of the positive voxels, a row of 8 along x at a time.
        let mut lo = IVec3::splat(BRICK);
        let mut hi = IVec3::splat(-1);
        for (r, row) in values.chunks_exact(BRICK as usize).enumerate() {
            let (Some(x0), Some(x1)) = (row.iter().position(|v| *v > 0.0), row.iter().rposition(|v| *v > 0.0)) else {
                continue;
            };
            let (y, z) = (r as i32 & (BRICK - 1), r as i32 >> BRICK_LOG2);
            lo = lo.min(IVec3::new(x0 as i32, y, z));
            hi = hi.max(IVec3::new(x1 as i32, y, z));
        }
        self.clamped_negative += negatives;
        let key = origin >> BRICK_LOG2;
        if hi.x < 0 {
            // Nothing non-zero: the brick only clears what was there.
            if self.bricks.remove(&key).is_some() || self.constants.remove(&key).is_some() {
                // Keep the bbox as declared; the brick now reads as zero.
            }
            return Ok(());
        }
        let (lo, hi) = (origin + lo, origin + hi);
        if !self.bricks.contains_key(&key) || lo.cmplt(self.bbox_min).any() || hi.cmpgt(self.bbox_max).any() {
            self.reserve_extent(lo, hi)?;
        }
        self.constants.remove(&key);
        let mut brick = Box::new([0.0f32; BRICK_VOXELS]);
        for (d, &v) in brick.iter_mut().zip(values.iter()) {
            *d = v.max(0.0);
        }
        self.bricks.insert(key, brick);
        Ok(())
    }

    /// Fills the cube [origin, origin + size) with a constant (a VDB tile). `origin` and `size`
    /// must be multiples of the brick size. Limits are checked before anything is stored.
    pub fn fill_tile(&mut self, origin: IVec3, size: i32, v: f32) -> Result<()> {
        Self::check_value(v, origin)?;
        if size <= 0 || size % BRICK != 0 || (origin & (BRICK - 1)) != IVec3::ZERO {
            return Err(Error::InvalidArgument(format!("tile of size {size} at {origin} is not brick-aligned")));
        }
        let v = if v < 0.0 {
            self.clamped_negative += (size as u64).pow(3);
            0.0
        } else {
            v
        };
        if v == 0.0 {
            return Ok(());
        }
        self.reserve_extent(origin, origin + IVec3::splat(size - 1))?;
        let n = size / BRICK;
        let b0 = origin >> BRICK_LOG2;
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let key = b0 + IVec3::new(x, y, z);
                    if let Some(brick) = self.bricks.get_mut(&key) {
                        brick.fill(v);
                    } else {
                        self.constants.insert(key, v);
                    }
                }
            }
        }
        Ok(())
    }

    pub fn build(self) -> Result<DensityGrid> {
        if self.bricks.is_empty() && self.constants.is_empty() {
            return Ok(DensityGrid::empty());
        }
        // Tight voxel bbox of what is actually non-zero would need a scan; the reserved bbox is
        // what callers declared and is tight for VDB leaves/tiles and dense input.
        let brick_min = self.bbox_min >> BRICK_LOG2;
        let brick_max = self.bbox_max >> BRICK_LOG2;
        let brick_dims = brick_max - brick_min + IVec3::ONE;
        let table_len = brick_dims.x as usize * brick_dims.y as usize * brick_dims.z as usize;
        let mut table = vec![EMPTY; table_len];
        let index = |k: IVec3| {
            let b = k - brick_min;
            (b.x + brick_dims.x * (b.y + brick_dims.y * b.z)) as usize
        };
        let mut max_value = 0.0f32;
        let mut constants = Vec::new();
        let mut const_ids: HashMap<u32, u32> = HashMap::new();
        for (k, v) in self.constants {
            let id = *const_ids.entry(v.to_bits()).or_insert_with(|| {
                constants.push(v);
                (constants.len() - 1) as u32
            });
            table[index(k)] = CONSTANT_BIT | id;
            max_value = max_value.max(v);
        }
        let mut keys: Vec<IVec3> = self.bricks.keys().copied().collect();
        keys.sort_by_key(|k| (k.z, k.y, k.x));
        let mut bricks_map = self.bricks;
        let mut bricks = Vec::with_capacity(keys.len());
        for k in keys {
            let b = bricks_map.remove(&k).unwrap();
            max_value = b.iter().fold(max_value, |m, &v| m.max(v));
            bricks.push(*b);
            table[index(k)] = bricks.len() as u32;
        }
        Ok(DensityGrid {
            brick_min,
            brick_dims,
            table,
            bricks,
            constants,
            bbox_min: self.bbox_min,
            bbox_max: self.bbox_max,
            max_value,
        })
    }
}

impl super::trilinear::Lattice<f32> for &DensityGrid {
    #[inline(always)]
    fn at(&self, c: IVec3) -> f32 {
        self.voxel(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_roundtrip_and_trilinear() {
        let dims = IVec3::new(5, 4, 3);
        let vals: Vec<f32> = (0..60).map(|i| i as f32 * 0.5).collect();
        let g = DensityGrid::from_dense(IVec3::new(-3, 2, 7), dims, &vals, GridLimits::default()).unwrap();
        assert_eq!(g.voxel(IVec3::new(-3, 2, 7)), 0.0);
        assert_eq!(g.voxel(IVec3::new(-2, 2, 7)), 0.5);
        assert_eq!(g.voxel(IVec3::new(1, 5, 9)), 59.0 * 0.5);
        assert_eq!(g.voxel(IVec3::new(2, 5, 9)), 0.0);
        // Halfway between x=-2 (0.5) and x=-1 (1.0).
        assert!((g.sample(Vec3::new(-1.5, 2.0, 7.0)) - 0.75).abs() < 1e-6);
        // Ramp to zero outside the stored voxels.
        assert!((g.sample(Vec3::new(1.5, 5.0, 9.0)) - 59.0 * 0.25).abs() < 1e-5);
        assert_eq!(g.max_value(), 29.5);
        assert_eq!(g.max_in_box(IVec3::new(-10, -10, -10), IVec3::new(-2, 2, 7)), 0.5);
    }

    #[test]
    fn tiles_stay_sparse_and_limits_refuse_before_allocating() {
        let mut b = DensityGridBuilder::new(GridLimits::default());
        b.fill_tile(IVec3::new(1024, 0, 0), 128, 2.0).unwrap();
        b.set(IVec3::new(1, 1, 1), 3.0).unwrap();
        let g = b.build().unwrap();
        assert_eq!(g.voxel(IVec3::new(1100, 50, 127)), 2.0);
        assert_eq!(g.voxel(IVec3::new(1, 1, 1)), 3.0);
        let (sum, count) = g.sum_and_count_nonzero();
        assert_eq!(count, 128u64.pow(3) + 1);
        assert_eq!(sum, 2.0 * 128f64.powi(3) + 3.0);

        let mut b = DensityGridBuilder::new(GridLimits::default());
        let err = b.fill_tile(IVec3::splat(0), 4096, 1.0).unwrap_err();
        assert!(err.to_string().contains("over the limit"), "{err}");
    }

    #[test]
    fn set_leaf_is_tight_and_checked() {
        let mut b = DensityGridBuilder::new(GridLimits::default());
        let mut v = [0.0f32; BRICK_VOXELS];
        v[voxel_offset(IVec3::new(2, 3, 4))] = 1.5;
        v[voxel_offset(IVec3::new(5, 1, 6))] = 0.5;
        v[voxel_offset(IVec3::new(7, 7, 7))] = -1.0;
        b.set_leaf(IVec3::new(16, -8, 0), &v).unwrap();
        assert_eq!(b.clamped_negative(), 1);
        assert!(b.set_leaf(IVec3::new(3, 0, 0), &v).is_err());
        let mut bad = v;
        bad[9] = f32::INFINITY;
        assert!(b.set_leaf(IVec3::new(0, 0, 0), &bad).is_err());
        let g = b.build().unwrap();
        assert_eq!(g.bbox(), (IVec3::new(18, -7, 4), IVec3::new(21, -5, 6)));
        assert_eq!(g.voxel(IVec3::new(18, -5, 4)), 1.5);
        assert_eq!(g.voxel(IVec3::new(23, -1, 7)), 0.0);
        let mut n = 0;
        g.for_each_brick(|o, r| {
            n += 1;
            assert_eq!(o, IVec3::new(16, -8, 0));
            assert!(matches!(r, BrickRef::Dense(_)));
        });
        assert_eq!(n, 1);
    }

    #[test]
    fn nan_is_an_error_and_negative_is_clamped() {
        let mut b = DensityGridBuilder::new(GridLimits::default());
        assert!(b.set(IVec3::ZERO, f32::NAN).is_err());
        b.set(IVec3::ONE, -1.0).unwrap();
        assert_eq!(b.clamped_negative(), 1);
    }
}
