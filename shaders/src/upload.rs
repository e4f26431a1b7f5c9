//! Host-side packing of core types into GPU buffers.

use glam::{Affine3A, Vec3};
use std::sync::Arc;

use crate::context::{Buf, GpuContext, GpuError};
use volscatter_core::medium::key::grid_fingerprint;
use volscatter_core::medium::grid::{self, BRICK_VOXELS};
use volscatter_core::medium::Medium;
use volscatter_core::ScatteringGrid;

/// A 3x4 affine as three rows (WGSL `array<vec4<f32>, 3>`).
pub fn affine_rows(a: &Affine3A) -> [[f32; 4]; 3] {
    let m = glam::Mat4::from(*a);
    [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array()]
}

/// The medium's density as it is stored on the CPU (`DensityGrid`: a table over the bounding
/// box in 8^3 bricks, the bricks of voxels, the constant tiles), in one buffer of u32 words
/// (floats as their bits): table, then bricks, then constants. Empty space costs one table
/// word, so a sparse cloud takes its own memory on the GPU, not its bounding box's; lookups
/// (the prelude wgsl/density.wgsl) read the same voxels as `DensityGrid::voxel`.
pub struct BrickedDensity {
    /// Table corner in bricks; w = offset of the first brick's voxels in `words`.
    pub brick_min: [i32; 4],
    /// Table size in bricks; w = offset of the constants in `words`.
    pub brick_dims: [u32; 4],
    pub words: Vec<u32>,
}

// wgsl/density.wgsl hard-codes the grid's encoding.
const _: () = assert!(grid::BRICK_LOG2 == 3 && grid::EMPTY == 0 && grid::CONSTANT_BIT == 0x8000_0000);

/// Bytes `bricked_density` will take, to check limits before building it.
pub fn bricked_density_bytes(medium: &Medium) -> u64 {
    let (_, _, table, bricks, constants) = medium.grid.storage();
    (table.len() as u64 + bricks.len() as u64 * BRICK_VOXELS as u64 + constants.len() as u64) * 4
}

pub fn bricked_density(medium: &Medium) -> BrickedDensity {
    let (brick_min, brick_dims, table, bricks, constants) = medium.grid.storage();
    let mut words = Vec::with_capacity((bricked_density_bytes(medium) / 4) as usize);
    words.extend_from_slice(table);
    let bricks_at = words.len() as i32;
    words.extend(bricks.iter().flat_map(|b| b.iter().map(|v| v.to_bits())));
    let constants_at = words.len() as u32;
    words.extend(constants.iter().map(|v| v.to_bits()));
    BrickedDensity {
        brick_min: [brick_min.x, brick_min.y, brick_min.z, bricks_at],
        brick_dims: [brick_dims.x.max(0) as u32, brick_dims.y.max(0) as u32, brick_dims.z.max(0) as u32, constants_at],
        words,
    }
}

/// RGB grid as vec4 (WGSL arrays of vec3 have a 16-byte stride anyway).
pub fn rgb_as_vec4(data: &[Vec3]) -> Vec<[f32; 4]> {
    data.iter().map(|v| [v.x, v.y, v.z, 0.0]).collect()
}

pub fn grid_dims(g: &ScatteringGrid) -> [u32; 4] {
    [g.dims[0], g.dims[1], g.dims[2], 0]
}

/// The medium's density on the device (`bricked_density`), kept by the context while the
/// density grid is unchanged (`GpuContext::resident`, keyed by the grid's fingerprint): the
/// kernels that march the medium share it, and a session's frames upload it once.
pub struct ResidentDensity {
    pub brick_min: [i32; 4],
    pub brick_dims: [u32; 4],
    pub buffer: Buf,
}

pub fn resident_density(ctx: &GpuContext, medium: &Medium) -> Result<Arc<ResidentDensity>, GpuError> {
    ctx.check_storage_size("medium density", bricked_density_bytes(medium))?;
    ctx.resident("density", grid_fingerprint(&medium.grid), || {
        let d = bricked_density(medium);
        Ok(ResidentDensity { brick_min: d.brick_min, brick_dims: d.brick_dims, buffer: ctx.storage_buffer("density", bytemuck::cast_slice(&d.words))? })
    })
}

/// A key of `words`' exact bits and count (what `GpuContext::resident` compares).
pub fn words_key(words: &[u32]) -> u64 {
    volscatter_core::stages::diff::Bits::new().bytes(bytemuck::cast_slice(words)).finish()
}
