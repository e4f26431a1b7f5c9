//! What an `lpm` solve will hold, from the medium's world box and the settings alone, before
//! any voxel is read: for hosts that offer the out-of-core solve for large volumes (the
//! Blender add-on, through `vs_scene_lpm_estimate`). Every number comes from the formulas the
//! solver plans with (`stream::plan`/`working_bytes` in memory, `out_of_core::plan`/
//! `slab_bytes` out of core, `cell_bytes` below, which the solve's report uses too), so the
//! estimate cannot drift from the solve; estimate_tests in out_of_core_tests.rs checks it
//! against solves.
//!
//! Not counted: the medium itself (the host knows its voxels; with `medium.max_resolution` it
//! is the coarse grid), the density mip (about 1/7 of the medium) and the output grid
//! (about `output_resolution`^3 RGB values), all the same in memory and out of core.

use glam::Vec3;

use super::directions::{Directions, FACES};
use super::grid::LpmGrid;
use super::propagate::FaceFrame;
use super::slab_store::VALUE_BYTES;
use super::{out_of_core, stream, LpmSettings};
use crate::error::Result;

/// Bytes of the in-memory solve's per-cell arrays: density and sigma_t (16 bytes a cell), U of
/// two orders (`m` RGB values a cell each) and J (one RGB value a cell).
pub fn cell_bytes(cells: u64, m: usize) -> u64 {
    cells * 16 + (2 * m as u64 + 1) * cells * 12
}

/// Bytes of the out-of-core solve's scratch files: sigma_t, the density guide and J (one
/// value a cell each) and U of two orders (`m` a cell each).
pub fn scratch_bytes(cells: u64, m: usize) -> u64 {
    cells * (2 * m as u64 + 3) * VALUE_BYTES as u64
}

/// The estimate of one set of settings over one medium box.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LpmMemory {
    /// The propagation grid's cells along x, y, z.
    pub grid_dims: [usize; 3],
    /// In memory (`out_of_core: false`): the per-cell arrays plus the largest face's sweep
    /// buffers under the settings' `memory_budget` (the whole depth when it is 0); 0 when
    /// even one layer does not fit.
    pub in_memory_bytes: u64,
    /// Out of core: the largest face's slab (maps, T and the slab's boxes of the per-cell
    /// arrays) under `memory_budget`; 0 when even one layer does not fit.
    pub out_of_core_bytes: u64,
    /// Out of core: the scratch files on disk.
    pub scratch_bytes: u64,
}

/// The memory `lpm` with `settings` will use over a medium whose world box is `lo..hi`
/// (`Medium::world_bounds`). Invalid settings are an error; a `memory_budget` below one layer
/// is not: the figure it refuses is 0 (the solve would refuse with the size one layer needs).
pub fn memory(lo: Vec3, hi: Vec3, settings: &LpmSettings) -> Result<LpmMemory> {
    settings.validate()?;
    let (dims, _, _) = LpmGrid::geometry_of_box(lo, hi, settings.grid_resolution);
    let dirs = Directions::new(settings.lattice_side() as usize, settings.storage_per_face as usize);
    let (p, m, bins) = (dirs.per_face(), dirs.storage_len(), dirs.bins_per_face());
    let cells = dims.iter().map(|&d| d as u64).product::<u64>();
    let largest = |bytes: &dyn Fn(usize, usize) -> u64, layers: [usize; FACES]| (0..FACES).map(|f| bytes(FaceFrame::from_dims(dims, f).map_len(), layers[f])).max().unwrap_or(0);
    let in_memory_bytes = match stream::plan(dims, &dirs, settings.memory_budget) {
        Ok(layers) => cell_bytes(cells, m) + largest(&|map, l| stream::working_bytes(map, p, bins, l), layers),
        Err(_) => 0,
    };
    let out_of_core_bytes = match out_of_core::plan(dims, &dirs, m, settings.memory_budget) {
        Ok(layers) => largest(&|map, l| out_of_core::slab_bytes(map, p, bins, m, l), layers),
        Err(_) => 0,
    };
    Ok(LpmMemory { grid_dims: dims, in_memory_bytes, out_of_core_bytes, scratch_bytes: scratch_bytes(cells, m) })
}
