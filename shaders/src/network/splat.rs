//! The splat's accumulation on the GPU (`splat.wgsl`, a gather per grid point over the
//! particles). The particles' radiance towards the camera (N x D, `towards_viewer`), the
//! footprints and the final division with its nearest-particle fallback (`finish`) stay on
//! the CPU: each is one pass over particles or points, the accumulation is points x particles.

use bytemuck::{Pod, Zeroable};
use std::mem::size_of;

use crate::context::GpuContext;
use volscatter_core::solvers::network::backend::SplatInput;
use volscatter_core::solvers::network::splat;
use volscatter_core::solvers::{Progress, ScatteringGrid};
use volscatter_core::Error;

pub const WGSL: &str = include_str!("splat.wgsl");

/// Mirrors `struct Params` in splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SplatParams {
    pub dims: [u32; 4],
    pub cells: [u32; 4],
    pub inv_range: [f32; 4],
}
const _: () = assert!(size_of::<SplatParams>() == 48);

/// Mirrors `struct Particle` in splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuParticle {
    pub position_inv_spatial: [f32; 4],
    pub lo: [i32; 4],
    pub hi: [i32; 4],
    pub value_density: [f32; 4],
}
const _: () = assert!(size_of::<GpuParticle>() == 64);

const GROUP: u32 = 64;
const MAX_GROUPS: u32 = 65535;
/// Box tests (points x particles) per submission: 2^24, ~60 ms on lavapipe here (measured:
/// 2^29 tests in 2.1 s on the loaded 2-core machine), so
/// that a cancel is seen within the 100 ms contract; far less on a real GPU.
const TESTS_PER_CHUNK: u64 = 1 << 24;

/// Adds sigma_s x the particles' splatted radiance towards the camera into `grid` (core
/// splat.rs `splat_into`, with `accumulate` on the GPU).
pub fn splat(ctx: &GpuContext, grid: &mut ScatteringGrid, x: &SplatInput, progress: &dyn Progress) -> Result<(), Error> {
    let p = x.particles;
    let cells = grid.len() as u64;
    ctx.check_storage_size("network splat sums", cells * 16)?;
    ctx.check_storage_size("network splat particles", p.len() as u64 * size_of::<GpuParticle>() as u64)?;
    let values = splat::towards_viewer(p, x.radiance, x.dirs, x.medium.g, x.camera);
    let prep = splat::prepare(grid, x.medium, p, x.kernel_radius, x.range_sigma);
    let [nx, ny, nz] = grid.dims;
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
    let sums = ctx.zeroed_storage("network splat sums", cells * 16)?;
    let pipeline = ctx.pipeline("network/splat.wgsl", WGSL, "main")?;
    let chunk = (TESTS_PER_CHUNK / p.len().max(1) as u64).clamp(GROUP as u64, GROUP as u64 * MAX_GROUPS as u64) as u32;
    let mut first = 0u32;
    while (first as u64) < cells {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let count = chunk.min(cells as u32 - first);
        let groups = count.div_ceil(GROUP);
        let (gx, gy) = (groups.min(MAX_GROUPS), groups.div_ceil(MAX_GROUPS));
        let params = SplatParams { dims: [nx, ny, nz, p.len() as u32], cells: [first, count, gx * GROUP, 0], inv_range: [prep.inv_range, 0.0, 0.0, 0.0] };
        let params_buf = ctx.uniform("network splat params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &pipeline, &[&params_buf, &points_buf, &particles_buf, &sums], [gx, gy, 1]);
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
mod tests;
