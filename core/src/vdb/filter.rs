//! A float grid box-filtered to a working resolution as it is read, for media whose voxels do
//! not fit in memory (the scene's `medium.max_resolution`; issue 19's "a volume larger than
//! RAM").
//!
//! Design: two passes over the file, each through the reader's bounded window (bytes.rs), so
//! neither the file nor the full-resolution grid is ever held:
//! 1. the topology alone (no leaf buffer is read): the index box of the leaves and of the
//!    non-zero tiles, from which the integer factor `f` (the box's longest side over
//!    `max_resolution`, rounded up) and the coarse lattice follow;
//! 2. every leaf and tile, decoded one at a time and added into a dense f64 array of the
//!    coarse cells (`f`^3 fine voxels each, aligned to multiples of `f` in index space); the
//!    mean (absent voxels count as the background, 0) becomes the coarse grid.
//!
//! Memory: the coarse array (8 bytes a coarse cell, then the 4-byte grid built from it), the
//! reader's two windows (64 KiB each, more only for one block that is longer: the tree reader
//! walks the topology a second time beside the leaf buffers, so it keeps nothing per leaf,
//! tree.rs) and one leaf: nothing that grows with the file but the coarse array.
//! `FilterReport` gives each.
//!
//! The coarse grid is what a solver sees as the medium: values at coarse cell centres,
//! trilinear between them, as any grid. Leaf voxels are taken as the whole load takes them
//! (all 512 values, inactive ones included; negatives clamped to 0, counted; NaN or inf an
//! error); a tile adds its value times the voxels it shares with each cell. Overlapping nodes,
//! which a valid file does not have, are summed rather than overwritten.

use std::ops::RangeInclusive;
use std::path::Path;

use glam::{Affine3A, I64Vec3, IVec3, Vec3};

use super::tree;
use super::values::ValueKind;
use super::VdbFile;
use crate::error::{excerpt, Error, Result};
use crate::medium::{DensityGrid, DensityGridBuilder, GridLimits};

/// The most cells a box-filtered read keeps along the grid's longest side (the scene's
/// `medium.max_resolution`, `vs_scene_lpm_estimate`'s argument): checked once, where it comes
/// in, so the filter never meets a value out of range (it refuses; it does not clamp).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaxResolution(u32);

impl MaxResolution {
    /// 2: one coarse cell a side has no interior to interpolate, and from 2 up `lattice`'s
    /// factor fits i32. 4096: the coarse sums alone (8 bytes a cell) are 512 GiB at 4096^3; a
    /// read that fine is the whole load's (leave `max_resolution` out).
    pub const RANGE: RangeInclusive<u32> = 2..=4096;

    /// `cells` when in `RANGE`, else why not ("must be in 2..=4096, got 1"), for the caller to
    /// prefix with the name its user knows the value by.
    pub fn new(cells: u32) -> std::result::Result<Self, String> {
        if Self::RANGE.contains(&cells) {
            Ok(Self(cells))
        } else {
            Err(format!("must be in {}..={}, got {cells}", Self::RANGE.start(), Self::RANGE.end()))
        }
    }

    pub fn cells(self) -> u32 {
        self.0
    }
}

/// What a filtered load did and held.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FilterReport {
    /// Fine voxels per coarse cell side.
    pub factor: i32,
    /// Leaf-aligned index box `lo..hi` (exclusive) of the leaves and non-zero tiles.
    pub fine_box: (I64Vec3, I64Vec3),
    pub coarse_dims: IVec3,
    pub leaves: usize,
    /// Bytes of the coarse accumulator (f64 a cell).
    pub accumulator_bytes: u64,
    /// Largest read window held (0 when the file was in memory).
    pub peak_window_bytes: usize,
    /// Negative voxel values read as 0.
    pub clamped_negative: u64,
}

/// Pass 1: the box of the leaves and of the tiles that hold density (64-bit: a tile at the
/// edge of the index range ends past i32).
struct Extent<'a> {
    lo: I64Vec3,
    hi: I64Vec3,
    leaves: usize,
    path: &'a Path,
}

impl Extent<'_> {
    fn add(&mut self, origin: IVec3, size: i64) {
        let lo = origin.as_i64vec3();
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(lo + I64Vec3::splat(size));
    }
}

impl tree::Visitor for Extent<'_> {
    fn background(&mut self, value: &[f64]) -> Result<()> {
        super::density_background(self.path, value)
    }
    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], _active: bool) -> Result<()> {
        // A NaN tile is kept too, so that pass 2 reports it.
        let v = value[0] as f32;
        if v > 0.0 || v.is_nan() {
            self.add(origin, 1 << log2);
        }
        Ok(())
    }
    fn leaf(&mut self, _origin: IVec3, _mask: &[u64; 8], _values: &[f64]) -> Result<()> {
        Ok(())
    }
    fn wants_leaf(&mut self, origin: IVec3) -> bool {
        self.add(origin, 8);
        self.leaves += 1;
        false
    }
    fn topology_only(&self) -> bool {
        true
    }
}

/// Pass 2: sums of the fine voxels in each coarse cell.
struct Accumulate<'a> {
    f: i64,
    /// Coarse index of the array's first cell.
    c0: I64Vec3,
    dims: I64Vec3,
    sums: Vec<f64>,
    clamped_negative: u64,
    path: &'a Path,
}

impl Accumulate<'_> {
    #[inline]
    fn index(&self, c: I64Vec3) -> usize {
        let d = c - self.c0;
        d.x as usize + self.dims.x as usize * (d.y as usize + self.dims.y as usize * d.z as usize)
    }

    /// The value as the whole load stores it: f32, finite (the whole load's check), negatives 0.
    fn value(&mut self, v: f64, at: IVec3) -> Result<f32> {
        let v = v as f32;
        DensityGridBuilder::check_value(v, at)?;
        if v < 0.0 {
            self.clamped_negative += 1;
            return Ok(0.0);
        }
        Ok(v)
    }
}

impl tree::Visitor for Accumulate<'_> {
    fn background(&mut self, value: &[f64]) -> Result<()> {
        super::density_background(self.path, value)
    }

    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], _active: bool) -> Result<()> {
        let v = self.value(value[0], origin)?;
        if v == 0.0 {
            return Ok(());
        }
        let lo = origin.as_i64vec3();
        let hi = lo + I64Vec3::splat(1 << log2);
        let f = self.f;
        let (a, b) = (lo.div_euclid(I64Vec3::splat(f)), (hi - I64Vec3::ONE).div_euclid(I64Vec3::splat(f)));
        for z in a.z..=b.z {
            for y in a.y..=b.y {
                for x in a.x..=b.x {
                    let c = I64Vec3::new(x, y, z);
                    // Fine voxels the tile shares with cell c.
                    let n = (hi.min((c + I64Vec3::ONE) * f) - lo.max(c * f)).max(I64Vec3::ZERO).as_dvec3();
                    let i = self.index(c);
                    self.sums[i] += v as f64 * n.x * n.y * n.z;
                }
            }
        }
        Ok(())
    }

    fn leaf(&mut self, origin: IVec3, _mask: &[u64; 8], values: &[f64]) -> Result<()> {
        // The coarse cell of each of the leaf's 8 voxels along each axis, once per leaf (not
        // three 64-bit divisions per voxel: this is the hot loop of a 10^9-voxel file).
        let (o, f) = (origin.as_i64vec3(), self.f);
        let axis = |a: i64, c0: i64| -> [usize; 8] { std::array::from_fn(|k| ((a + k as i64).div_euclid(f) - c0) as usize) };
        let (cx, cy, cz) = (axis(o.x, self.c0.x), axis(o.y, self.c0.y), axis(o.z, self.c0.z));
        let (nx, ny) = (self.dims.x as usize, self.dims.y as usize);
        for (i, &raw) in values.iter().enumerate() {
            // VDB order: x << 6 | y << 3 | z. A leaf's origin is a multiple of 8: no overflow.
            let (x, y, z) = (i >> 6, (i >> 3) & 7, i & 7);
            let v = self.value(raw, origin + IVec3::new(x as i32, y as i32, z as i32))?;
            if v > 0.0 {
                // `index` of the voxel's coarse cell.
                self.sums[cx[x] + nx * (cy[y] + ny * cz[z])] += v as f64;
            }
        }
        Ok(())
    }
}

/// The factor and coarse lattice (first cell, cells) for at most `max_resolution` cells along
/// the box's longest side. The cells are aligned to multiples of `f`, so a box that does not
/// start on one straddles a cell more than extent / f: then `f` grows to extent / (m - 1),
/// which leaves at most m. The coarse indices (the fine ones over `f`) fit i32; `f` itself may
/// reach 2^32 (m = 2 on the widest box).
pub(crate) fn lattice(lo: I64Vec3, hi: I64Vec3, max_resolution: MaxResolution) -> (i64, I64Vec3, I64Vec3) {
    let extent = (hi - lo).max_element().max(1);
    let m = max_resolution.cells() as i64;
    let cells = |f: i64| {
        let c0 = lo.div_euclid(I64Vec3::splat(f));
        let c1 = (hi - I64Vec3::ONE).div_euclid(I64Vec3::splat(f));
        (c0, c1 - c0 + I64Vec3::ONE)
    };
    let mut f = (extent + m - 1) / m;
    if cells(f).1.max_element() > m {
        f = (extent + m - 2) / (m - 1);
    }
    let (c0, dims) = cells(f);
    (f, c0, dims)
}

/// Coarse cell c covers fine voxels c f .. c f + f - 1: its centre is c f + (f - 1) / 2.
fn coarse_to_fine(f: i64) -> Affine3A {
    Affine3A::from_translation(Vec3::splat(0.5 * (f - 1) as f32)) * Affine3A::from_scale(Vec3::splat(f as f32))
}

/// What a float grid will be as a medium, from its topology alone (pass 1: no leaf buffer is
/// decoded, a sparse 1024^3 grid costs its node headers): for hosts that size a volume before
/// reading its voxels (`vs_scene_lpm_estimate`).
#[derive(Clone, Debug, PartialEq)]
pub struct MediumSize {
    /// Leaf-aligned index box `lo..hi` (exclusive) of the leaves and non-zero tiles: the
    /// voxels a whole load holds densely (`hi - lo` of them along each axis).
    pub fine_box: (I64Vec3, I64Vec3),
    pub leaves: usize,
    /// Fine voxels per coarse cell side (1 without `max_resolution`).
    pub factor: i64,
    /// Voxels (cells) of the grid the medium will hold, along x, y, z.
    pub dims: I64Vec3,
    /// The held grid's index-to-object map and its index box as `Medium::index_bounds` gives it
    /// (the voxel box widened by one voxel): `Medium::world_bounds` once the object's
    /// transform is applied. Of the leaf box, which may be wider than the active voxels'.
    pub index_to_object: Affine3A,
    pub index_bounds: (Vec3, Vec3),
}

impl VdbFile {
    /// `MediumSize` of float grid `i` read whole (`max_resolution` None) or box-filtered to
    /// at most `max_resolution` cells a side; None for a grid with no leaf or non-zero tile.
    pub fn medium_size(&self, i: usize, max_resolution: Option<MaxResolution>) -> Result<Option<MediumSize>> {
        let head = self.grid_head(i)?;
        let mut extent = Extent { lo: I64Vec3::MAX, hi: I64Vec3::MIN, leaves: 0, path: &self.path };
        self.visit_tree_windowed(i, ValueKind::FLOAT, &mut extent, None)?;
        if extent.lo.cmpge(extent.hi).any() {
            return Ok(None);
        }
        let fine_xf = head.transform.to_affine3a();
        let (factor, first, dims, xf) = match max_resolution {
            None => (1, extent.lo, extent.hi - extent.lo, fine_xf),
            Some(n) => {
                let (f, c0, dims) = lattice(extent.lo, extent.hi, n);
                (f, c0, dims, fine_xf * coarse_to_fine(f))
            }
        };
        let xf = self.checked_transform(i, &head, xf)?; // as the load will
        let index_bounds = ((first - I64Vec3::ONE).as_vec3(), (first + dims).as_vec3());
        Ok(Some(MediumSize { fine_box: (extent.lo, extent.hi), leaves: extent.leaves, factor, dims, index_to_object: xf, index_bounds }))
    }

    /// Float grid `i` box-filtered to at most `max_resolution` cells along its longest side
    /// (see the module docs), with the coarse grid's index-to-world map.
    pub fn load_float_grid_filtered(&self, i: usize, max_resolution: MaxResolution, limits: GridLimits) -> Result<(DensityGrid, Affine3A, FilterReport)> {
        let name = self.grids[i].name.clone();
        let in_grid = |e: Error| match e {
            Error::InvalidArgument(m) => Error::format(&self.path, format!("grid `{}`: {m}", excerpt(&name))),
            e => e,
        };
        let head = self.grid_head(i)?;
        let mut extent = Extent { lo: I64Vec3::MAX, hi: I64Vec3::MIN, leaves: 0, path: &self.path };
        let (_, window1) = self.visit_tree_windowed(i, ValueKind::FLOAT, &mut extent, None).map_err(in_grid)?;
        let fine_xf = head.transform.to_affine3a();
        let mut report = FilterReport { leaves: extent.leaves, ..Default::default() };
        if extent.lo.cmpge(extent.hi).any() {
            report.peak_window_bytes = window1;
            return Ok((DensityGrid::empty(), self.checked_transform(i, &head, fine_xf)?, report));
        }
        let (f, c0, dims) = lattice(extent.lo, extent.hi, max_resolution);
        // Before pass 2 reads every leaf: a transform the medium cannot use fails at once.
        let xf = self.checked_transform(i, &head, fine_xf * coarse_to_fine(f))?;
        let cells = crate::budget::checked_product("filtered density grid", &[dims.x as u64, dims.y as u64, dims.z as u64])?;
        crate::budget::check_elements::<f64>("filtered density grid (coarse sums)", cells)?;
        let mut acc = Accumulate { f, c0, dims, sums: vec![0.0; cells as usize], clamped_negative: 0, path: &self.path };
        let (_, window2) = self.visit_tree_windowed(i, ValueKind::FLOAT, &mut acc, None).map_err(in_grid)?;
        let volume = (f as f64).powi(3);
        let means: Vec<f32> = acc.sums.iter().map(|s| (s / volume) as f32).collect();
        let (c0, dims) = (c0.as_ivec3(), dims.as_ivec3());
        report.factor = i32::try_from(f).unwrap_or(i32::MAX);
        report.fine_box = (extent.lo, extent.hi);
        report.coarse_dims = dims;
        report.accumulator_bytes = cells * 8;
        report.peak_window_bytes = window1.max(window2);
        report.clamped_negative = acc.clamped_negative;
        drop(acc);
        let grid = DensityGrid::from_dense(c0, dims, &means, limits)?;
        Ok((grid, xf, report))
    }
}

/// `load_density` box-filtered to at most `max_resolution` cells a side (see the module docs):
/// the file is read through a bounded window, never whole.
pub fn load_density_filtered(path: &Path, grid: Option<&str>, max_resolution: MaxResolution, limits: GridLimits) -> Result<(DensityGrid, Affine3A, FilterReport)> {
    let f = VdbFile::open(path, u64::MAX)?;
    let i = f.find_density_grid(grid)?;
    f.load_float_grid_filtered(i, max_resolution, limits)
}
