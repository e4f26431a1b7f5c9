//! `photon-grid`'s reconstruction on the GPU (`reconstruct.wgsl`): S towards the camera at the
//! output resolution from the cache's tallies, both upsamplings (trilinear, the paper's
//! physical), one invocation per output voxel; same inputs and output as volscatter-core's
//! `reconstruct::scattering_towards` (the `PhotonBackend::reconstruct` default).
//!
//! The tallies (the ring's integer sum, turned into floats with each cell's mass on the CPU:
//! cache.rs `Tallies::from_fixed`) go up once per frame with the bricked density
//! (upload.rs); the output is computed a slab of planes at a time into one buffer and read back
//! after each, so that a cancel is seen between slabs and an output larger than a storage
//! buffer still fits.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::{offset_of, size_of};

use crate::context::GpuContext;
use crate::pop::light::read_rgb;
use crate::upload::{affine_rows, bricked_density_bytes};
use volscatter_core::medium::Medium;
use volscatter_core::solvers::photon_grid::cache::Tallies;
use volscatter_core::solvers::photon_grid::upsample::Upsampler;
use volscatter_core::solvers::photon_grid::{PhotonGridSettings, Upsampling};
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::{Error, Result};

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "hg"], "photon_grid/reconstruct.wgsl");

/// Mirrors `struct Params` in reconstruct.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct ReconstructParams {
    pub out_i2w: [[f32; 4]; 3],
    pub density_w2i: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub cell_w2i: [[f32; 4]; 3],
    pub cell_i2w: [[f32; 4]; 3],
    pub cell_dims: [i32; 4],
    pub out_dims: [u32; 4],
    pub camera: [f32; 4],
    pub sigma_s: [f32; 4],
    pub physical: [f32; 4],
}
const _: () = {
    assert!(size_of::<ReconstructParams>() == 304);
    assert!(offset_of!(ReconstructParams, cell_dims) == 224);
};

/// Output voxels per dispatch (the cancel flag is read between two). A GPU takes 2^22 (64 MiB
/// of output, a few milliseconds even with the physical upsampling's 27 cells a lobe); a
/// software adapter (lavapipe, on the CPU's cores) 2^16, so that a slab takes well under a
/// second at the physical upsampling.
const SLAB_VOXELS_GPU: u64 = 1 << 22;
const SLAB_VOXELS_SOFTWARE: u64 = 1 << 16;

/// Vec4s per cell and lobe (reconstruct.wgsl `cells`).
const CELL_VEC4S: usize = 3;

/// The tallies of every lobe as reconstruct.wgsl reads them (its `cells` doc), with each cell's
/// normalised mean density from `Upsampler` (zero unless `physical`).
fn pack_cells(medium: &Medium, tallies: &[Tallies], physical: bool) -> Vec<[f32; 4]> {
    let mut out = Vec::with_capacity(tallies.iter().map(|t| t.mass.len() * CELL_VEC4S).sum());
    for t in tallies {
        let upsampler = physical.then(|| Upsampler::new(medium, t));
        for i in 0..t.mass.len() {
            let density = upsampler.as_ref().map_or(0.0, |u| u.cell_density[i]);
            out.extend([t.flux[i].extend(t.weight[i]).to_array(), t.moment[i].extend(t.order[i]).to_array(), [t.mass[i], density, 0.0, 0.0]]);
        }
    }
    out
}

/// `PhotonBackend::reconstruct` on the GPU: S towards `camera` on
/// `ScatteringGrid::over_medium(medium, settings.output_resolution)` from `tallies` (all on
/// one cache frame), upsampled by `settings.upsampling`. Refuses with `Error::Device` (too
/// large) what does not fit the adapter's storage buffers; `Cancelled` between slabs.
pub fn scattering_towards(ctx: &GpuContext, medium: &Medium, tallies: &[Tallies], camera: Vec3, settings: &PhotonGridSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
    let mut out = ScatteringGrid::over_medium(medium, settings.output_resolution)?;
    let [nx, ny, nz] = out.dims;
    let cells_per_lobe = tallies.first().map_or(0, |t| t.mass.len());
    if tallies.iter().any(|t| t.mass.len() != cells_per_lobe || t.frame.dims != tallies[0].frame.dims) {
        return Err(Error::InvalidArgument("photon-grid reconstruction: the lobes' caches differ in size".into()));
    }
    let physical = settings.upsampling == Upsampling::Physical;

    // Sizes checked before anything is built or allocated.
    let cell_bytes = (tallies.len() * cells_per_lobe * CELL_VEC4S * 16) as u64;
    ctx.check_storage_size("photon cache tallies (solver.cache_resolution)", cell_bytes)?;
    ctx.check_storage_size("medium density", bricked_density_bytes(medium))?;
    let plane = nx as u64 * ny as u64;
    let max_bytes = (ctx.limits.max_storage_buffer_binding_size as u64).min(ctx.limits.max_buffer_size);
    let budget = if ctx.is_software() { SLAB_VOXELS_SOFTWARE } else { SLAB_VOXELS_GPU };
    let planes = (budget / plane).min(max_bytes / (plane * 16)).min(nz as u64).max(1) as u32;
    let slab_bytes = plane * planes as u64 * 16;
    ctx.check_storage_size("scattering grid slab (solver.output_resolution)", slab_bytes)?;

    let bricks = crate::upload::resident_density(ctx, medium)?;
    let density: &wgpu::Buffer = &bricks.buffer;
    let cells = ctx.storage_buffer("photon cache tallies", bytemuck::cast_slice(&pack_cells(medium, tallies, physical)))?;
    let slab = ctx.zeroed_storage("scattering grid slab", slab_bytes)?;
    let (cell_dims, cell_i2w, cell_w2i) = match tallies.first() {
        Some(t) => ([t.frame.dims[0] as i32, t.frame.dims[1] as i32, t.frame.dims[2] as i32, cells_per_lobe as i32], t.frame.index_to_world, t.world_to_cell),
        None => ([0; 4], Default::default(), Default::default()),
    };
    // The constants Upsampler::new measures (the same for every lobe: they depend on the
    // medium and the cache's frame).
    let (density_norm, r, sigma_mean) = match tallies.first().filter(|_| physical).map(|t| Upsampler::new(medium, t)) {
        Some(u) => (u.density_norm, u.r, u.sigma_s),
        None => (0.0, 0.0, 0.0),
    };
    let base = ReconstructParams {
        out_i2w: affine_rows(&out.index_to_world),
        density_w2i: affine_rows(&medium.world_to_index),
        density_brick_min: bricks.brick_min,
        density_brick_dims: bricks.brick_dims,
        cell_w2i: affine_rows(&cell_w2i),
        cell_i2w: affine_rows(&cell_i2w),
        cell_dims,
        out_dims: [nx, ny, 0, tallies.len() as u32],
        camera: camera.extend(medium.g).to_array(),
        sigma_s: (medium.albedo * medium.density_scale).extend(sigma_mean).to_array(),
        physical: [density_norm, r, 0.0, physical as u32 as f32],
    };
    let pipeline = ctx.pipeline("photon_grid/reconstruct.wgsl", WGSL, "main")?;
    for first in (0..nz).step_by(planes as usize) {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let count = planes.min(nz - first);
        let params = ReconstructParams { out_dims: [nx, ny, first, base.out_dims[3]], ..base };
        let params = ctx.uniform("photon reconstruct params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &pipeline, &[&params, density, &cells, &slab], [nx.div_ceil(8), ny.div_ceil(8), count]);
        ctx.submit_and_wait(enc)?;
        let at = (plane * first as u64) as usize;
        let n = plane * count as u64;
        out.data[at..at + n as usize].copy_from_slice(&read_rgb(ctx, &slab, n)?);
    }
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    Ok(out)
}
