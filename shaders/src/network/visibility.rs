//! The visibility network on the GPU (core network/visibility.rs `build`): per direction a key
//! (pixel, depth, particle) per particle and, with `Opacity::Boundary`, its optical depth to
//! the boundary (`keys.wgsl`); a bitonic sort of each direction's keys (sort.rs); then each
//! particle's upstream neighbour (the entry before it in its pixel) and the gap's opacity
//! (`links.wgsl`). Directions go in chunks (bounded buffers, a look at cancellation between
//! chunks and sort submissions); each chunk's lists are read back into `DirectionLinks`, which
//! the session keeps on the host like the CPU's.
//!
//! The keys are the CPU's bit for bit (the bases come from the host, the arithmetic is written
//! out as glam does it), so the lists are identical; the opacities agree to float rounding of
//! the march (the GPU's exp and fused operations).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::size_of;

use super::sort::{self, groups_for};
use crate::context::GpuContext;
use crate::upload::{affine_rows, bricked_density_bytes};
use volscatter_core::sampling::orthonormal_basis;
use volscatter_core::solvers::network::backend::VisibilityInput;
use volscatter_core::solvers::network::settings::Opacity;
use volscatter_core::solvers::network::visibility::{march_step, DirectionLinks};
use volscatter_core::stages::Progress;
use volscatter_core::Error;

pub const KEYS_WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box", "optics", "network_visibility"], "network/keys.wgsl");
pub const LINKS_WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box", "optics", "network_visibility"], "network/links.wgsl");

/// Mirrors `struct Params` in wgsl/network_visibility.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct VisibilityParams {
    pub density_w2i: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub density_scale: [f32; 4],
    pub bounds_lo: [f32; 4],
    pub bounds_hi: [f32; 4],
    pub centre_radius: [f32; 4],
    pub counts: [u32; 4],
    pub modes: [u32; 4],
    pub misc: [f32; 4],
}
const _: () = assert!(size_of::<VisibilityParams>() == 192);

/// Sort keys per chunk of directions (at least one direction's list): 2^17 keys, each with
/// its march to the boundary, took 0.87 s on lavapipe here (N 1024 x D 128, keys, sort,
/// links and readback; the loaded 2-core machine), the longest wait for a cancel; on a real
/// GPU a chunk is a few ms, its ~100 sort dispatches included.
const KEYS_PER_CHUNK: u64 = 1 << 17;

pub fn visibility(ctx: &GpuContext, x: &VisibilityInput, progress: &dyn Progress) -> Result<Vec<DirectionLinks>, Error> {
    visibility_chunked(ctx, x, KEYS_PER_CHUNK, progress)
}

/// `visibility` with chunks of at most `keys_per_chunk` sort keys (at least one direction).
pub fn visibility_chunked(ctx: &GpuContext, x: &VisibilityInput, keys_per_chunk: u64, progress: &dyn Progress) -> Result<Vec<DirectionLinks>, Error> {
    let (medium, p) = (x.medium, x.particles);
    let n = p.len() as u64;
    if n == 0 || x.dirs.is_empty() {
        return Ok(x.dirs.iter().map(|_| DirectionLinks { order: Vec::new(), up: Vec::new(), alpha: Vec::new() }).collect());
    }
    // Pixels are u32 keys below the padding key u32::MAX.
    if (x.window as u64).pow(2) >= u32::MAX as u64 {
        return Err(Error::Device(format!("network window {} x {} exceeds the GPU's 32-bit pixel keys", x.window, x.window)));
    }
    let len = n.next_power_of_two();
    let chunk = (keys_per_chunk / len).clamp(1, x.dirs.len() as u64);
    for (what, bytes) in [
        ("density", bricked_density_bytes(medium)),
        ("network sort keys", chunk * len * 16),
        ("network optical depths", chunk * n * 16),
        ("network opacities", chunk * n * 16),
    ] {
        ctx.check_storage_size(what, bytes)?;
    }
    if chunk * len > u32::MAX as u64 {
        return Err(Error::Device(format!("network visibility: {n} particles exceed the GPU sort's 2^32 keys")));
    }
    let (len, n32, chunk) = (len as u32, n as u32, chunk as u32);
    let density = crate::upload::resident_density(ctx, medium)?;
    let (lo, hi) = medium.world_bounds();
    let mut params = VisibilityParams {
        density_w2i: affine_rows(&medium.world_to_index),
        density_brick_min: density.brick_min,
        density_brick_dims: density.brick_dims,
        density_scale: medium.density_scale.extend(0.0).to_array(),
        bounds_lo: lo.extend(0.0).to_array(),
        bounds_hi: hi.extend(0.0).to_array(),
        centre_radius: x.centre.extend(x.radius).to_array(),
        counts: [n32, x.window, len, chunk],
        modes: [0, if x.opacity == Opacity::Boundary { 0 } else { 1 }, 0, 0],
        misc: [march_step(medium), 0.0, 0.0, 0.0],
    };
    let density: &wgpu::Buffer = &density.buffer;
    let positions: Vec<[f32; 4]> = p.position.iter().map(|q| q.extend(0.0).to_array()).collect();
    let positions = ctx.storage_buffer("network particles", bytemuck::cast_slice(&positions))?;
    let keys = ctx.zeroed_storage("network sort keys", chunk as u64 * len as u64 * 16)?;
    let to_boundary = ctx.zeroed_storage("network optical depths", chunk as u64 * n * 16)?;
    let order = ctx.zeroed_storage("network list order", chunk as u64 * n * 4)?;
    let up = ctx.zeroed_storage("network upstream", chunk as u64 * n * 4)?;
    let alpha = ctx.zeroed_storage("network opacities", chunk as u64 * n * 16)?;
    let keys_k = ctx.pipeline("network/keys.wgsl", KEYS_WGSL, "main")?;
    let links_k = ctx.pipeline("network/links.wgsl", LINKS_WGSL, "main")?;
    let mut out = Vec::with_capacity(x.dirs.len());
    for dirs in x.dirs.chunks(chunk as usize) {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let c = dirs.len() as u32;
        // The bases on the host: the GPU then bins with the CPU's very axes.
        let basis: Vec<[f32; 4]> = dirs
            .iter()
            .flat_map(|&w| {
                let (u, v) = orthonormal_basis(w);
                [u, v, w].map(|a| a.extend(0.0).to_array())
            })
            .collect();
        let basis = ctx.storage_buffer("network bases", bytemuck::cast_slice(&basis))?;
        let (groups, row) = groups_for(c * len);
        params.counts[3] = c;
        params.modes[0] = row;
        let keys_params = ctx.uniform("network keys params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &keys_k, &[&keys_params, density, &positions, &basis, &keys, &to_boundary], groups);
        ctx.submit_and_wait(enc)?;
        sort::sort(ctx, &keys, len, c, progress)?;
        let (groups, row) = groups_for(c * n32);
        params.modes[0] = row;
        let links_params = ctx.uniform("network links params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &links_k, &[&links_params, density, &positions, &basis, &keys, &to_boundary, &order, &up, &alpha], groups);
        ctx.submit_and_wait(enc)?;
        let words = c as u64 * n;
        let order_back = ctx.read_buffer(&order, words * 4)?;
        let up_back = ctx.read_buffer(&up, words * 4)?;
        let alpha_back = ctx.read_buffer(&alpha, words * 16)?;
        let (order_back, up_back): (&[u32], &[u32]) = (bytemuck::cast_slice(&order_back), bytemuck::cast_slice(&up_back));
        let alpha_back: &[[f32; 4]] = bytemuck::cast_slice(&alpha_back);
        for d in 0..c as usize {
            let r = d * n as usize..(d + 1) * n as usize;
            out.push(DirectionLinks {
                order: order_back[r.clone()].to_vec(),
                up: up_back[r.clone()].to_vec(),
                alpha: alpha_back[r].iter().map(|a| Vec3::new(a[0], a[1], a[2])).collect(),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
#[path = "visibility_tests.rs"]
pub(crate) mod tests;
