//! The splat's accumulation on the GPU, binned: the output grid is cut into tiles of T^3
//! points and each particle listed in the tiles its kernel box overlaps (`bin.wgsl`, the
//! (tile, particle) keys sorted by sort.rs, each tile's run found by `ranges.wgsl`), so that
//! each grid point (`splat.wgsl`) visits only its tile's particles, in index order: the CPU's
//! sums, in the CPU's order. T starts at 4 and doubles while the pairs exceed `MAX_PAIRS` (at
//! a single tile it is the all-pairs gather). The particles' radiance towards the camera (N x
//! D, `towards_viewer`), the footprints, the pairs' prefix sum and the final division with its
//! nearest-particle fallback (`finish`) stay on the CPU: each is one pass over particles or
//! points.

use bytemuck::{Pod, Zeroable};
use std::mem::size_of;

use super::sort::{self, groups_for};
use crate::context::GpuContext;
use volscatter_core::solvers::network::backend::SplatInput;
use volscatter_core::solvers::network::splat::{self, Footprint};
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::Error;

pub const BIN_WGSL: &str = crate::wgsl::kernel_wgsl!(["network_splat"], "network/bin.wgsl");
pub const RANGES_WGSL: &str = crate::wgsl::kernel_wgsl!(["network_splat"], "network/ranges.wgsl");
pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["network_splat"], "network/splat.wgsl");

/// Mirrors `struct Params` in wgsl/network_splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SplatParams {
    pub dims: [u32; 4],
    pub tiles: [u32; 4],
    pub pairs: [u32; 4],
    pub inv_range: [f32; 4],
}
const _: () = assert!(size_of::<SplatParams>() == 64);

/// Mirrors `struct Particle` in wgsl/network_splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuParticle {
    pub position_inv_spatial: [f32; 4],
    pub lo: [i32; 4],
    pub hi: [i32; 4],
    pub value_density: [f32; 4],
}
const _: () = assert!(size_of::<GpuParticle>() == 64);

/// The smallest tile side: one 4^3 workgroup of splat.wgsl.
pub const FIRST_TILE: u32 = 4;
/// Most (tile, particle) pairs: a 64 MiB key buffer whose sort is ~250 passes.
const MAX_PAIRS: u64 = 1 << 22;
/// Box tests (points x particles of their tile, bounded by all the pairs) per dispatch: ~60 ms
/// on lavapipe here (2^29 tests took 2.1 s on the loaded 2-core machine), so that a cancel is
/// seen within the 100 ms contract; far less on a real GPU.
const TESTS_PER_DISPATCH: u64 = 1 << 24;

/// Tiles a footprint's box overlaps at tile side `t` (0 for an empty box).
fn tiles_overlapped(f: &Footprint, t: i32) -> u64 {
    if f.lo.cmpgt(f.hi).any() {
        return 0;
    }
    let span = f.hi / t - f.lo / t + 1;
    span.x as u64 * span.y as u64 * span.z as u64
}

/// Adds sigma_s x the particles' splatted radiance towards the camera into `grid` (core
/// splat.rs `splat_into`, with `accumulate` on the GPU).
pub fn splat(ctx: &GpuContext, grid: &mut ScatteringGrid, x: &SplatInput, progress: &dyn Progress) -> Result<(), Error> {
    splat_tiled(ctx, grid, x, FIRST_TILE, progress)
}

/// `splat` with tiles of at least `first_tile` points a side (a power of two, at least 4).
pub fn splat_tiled(ctx: &GpuContext, grid: &mut ScatteringGrid, x: &SplatInput, first_tile: u32, progress: &dyn Progress) -> Result<(), Error> {
    let p = x.particles;
    let cells = grid.len() as u64;
    ctx.check_storage_size("network splat sums", cells * 16)?;
    ctx.check_storage_size("network splat particles", p.len() as u64 * size_of::<GpuParticle>() as u64)?;
    let values = splat::towards_viewer(p, x.radiance, x.dirs, x.medium.g, x.camera);
    let prep = splat::prepare(grid, x.medium, p, x.kernel_radius, x.range_sigma);
    let [nx, ny, nz] = grid.dims;
    // The tile side: doubled until the pairs fit (one tile holding the grid lists every
    // particle once).
    let mut t = first_tile.max(FIRST_TILE);
    let pairs = loop {
        let pairs: u64 = prep.footprints.iter().map(|f| tiles_overlapped(f, t as i32)).sum();
        if pairs <= MAX_PAIRS || t >= nx.max(ny).max(nz) {
            break pairs;
        }
        t *= 2;
    };
    let len = pairs.next_power_of_two().max(1);
    let tiles = [nx.div_ceil(t), ny.div_ceil(t), nz.div_ceil(t)];
    let tile_count = tiles.iter().map(|&n| n as u64).product::<u64>();
    ctx.check_storage_size("network splat pairs", len * 16)?;
    ctx.check_storage_size("network splat tiles", tile_count * 8)?;
    if len > u32::MAX as u64 / 2 {
        return Err(Error::Device(format!("network splat: {pairs} (tile, particle) pairs exceed the GPU sort")));
    }
    let mut offsets = Vec::with_capacity(p.len());
    let mut next = 0u32;
    for f in &prep.footprints {
        offsets.push(next);
        next += tiles_overlapped(f, t as i32) as u32;
    }
    let points: Vec<[f32; 4]> = (0..cells as u32)
        .map(|c| {
            let q = grid.position(c % nx, (c / nx) % ny, c / (nx * ny));
            [q.x, q.y, q.z, prep.dens[c as usize]]
        })
        .collect();
    let particles: Vec<GpuParticle> = (0..p.len())
        .map(|i| {
            let (f, q, v) = (prep.footprints[i], p.position[i], values[i]);
            GpuParticle {
                position_inv_spatial: [q.x, q.y, q.z, f.inv_spatial],
                lo: [f.lo.x, f.lo.y, f.lo.z, 0],
                hi: [f.hi.x, f.hi.y, f.hi.z, 0],
                value_density: [v.x, v.y, v.z, p.density[i]],
            }
        })
        .collect();
    let points_buf = ctx.storage_buffer("network splat points", bytemuck::cast_slice(&points))?;
    let particles_buf = ctx.storage_buffer("network splat particles", bytemuck::cast_slice(&particles))?;
    let offsets_buf = ctx.storage_buffer("network splat offsets", bytemuck::cast_slice(&offsets))?;
    let keys = ctx.zeroed_storage("network splat pairs", len * 16)?;
    let ranges = ctx.zeroed_storage("network splat tiles", tile_count * 8)?;
    let sums = ctx.zeroed_storage("network splat sums", cells * 16)?;
    let (len, pairs) = (len as u32, pairs as u32);
    let mut params = SplatParams { dims: [nx, ny, nz, p.len() as u32], tiles: [t, tiles[0], tiles[1], tiles[2]], pairs: [pairs, len, 0, 0], inv_range: [prep.inv_range, 0.0, 0.0, 0.0] };
    // Binning: one invocation per particle (and per padding slot).
    let (groups, row) = groups_for((p.len() as u32).max(len - pairs));
    params.pairs[3] = row;
    let bin_params = ctx.uniform("network bin params", bytemuck::bytes_of(&params));
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    ctx.record(&mut enc, &*ctx.pipeline("network/bin.wgsl", BIN_WGSL, "main")?, &[&bin_params, &particles_buf, &offsets_buf, &keys], groups);
    ctx.submit_and_wait(enc)?;
    sort::sort(ctx, &keys, len, 1, progress)?;
    let (groups, row) = groups_for(pairs);
    params.pairs[3] = row;
    let ranges_params = ctx.uniform("network ranges params", bytemuck::bytes_of(&params));
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    ctx.record(&mut enc, &*ctx.pipeline("network/ranges.wgsl", RANGES_WGSL, "main")?, &[&ranges_params, &keys, &ranges], groups);
    ctx.submit_and_wait(enc)?;
    // The gather, a slab of workgroup layers (4 grid layers each) per dispatch: a layer tests
    // at most its points x the pairs of its tiles.
    let pipeline = ctx.pipeline("network/splat.wgsl", WGSL, "main")?;
    let layers = nz.div_ceil(4);
    let tests_per_layer = (nx as u64 * ny as u64 * 4 * pairs as u64 / tile_count.max(1)).max(1);
    let per_dispatch = (TESTS_PER_DISPATCH / tests_per_layer).clamp(1, layers as u64) as u32;
    let mut first = 0u32;
    while first < layers {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let count = per_dispatch.min(layers - first);
        params.pairs[2] = first;
        let params_buf = ctx.uniform("network splat params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &pipeline, &[&params_buf, &points_buf, &particles_buf, &keys, &ranges, &sums], [nx.div_ceil(4), ny.div_ceil(4), count]);
        ctx.submit_and_wait(enc)?;
        first += count;
    }
    let bytes = ctx.read_buffer(&sums, cells * 16)?;
    let sums: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    let num: Vec<glam::Vec3> = sums.iter().map(|s| glam::Vec3::new(s[0], s[1], s[2])).collect();
    let den: Vec<f32> = sums.iter().map(|s| s[3]).collect();
    splat::finish(grid, x.medium, p, &values, &prep.dens, &num, &den);
    Ok(())
}

#[cfg(test)]
#[path = "splat_tests.rs"]
pub(crate) mod tests;
