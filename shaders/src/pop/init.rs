//! POP's transmittance sweep on the GPU (`init.wgsl`): same inputs and outputs as
//! `volscatter_core::solvers::pop::init::sweep` followed by `accumulate::add_direct` into a
//! fresh J, written into the light's device buffers; only per-column sums come back.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use crate::pop::light::{read_rgb, GpuLight};
use volscatter_core::solvers::pop::backend::SweepSums;

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["hg", "columns"], "pop/init.wgsl");

/// Mirrors `struct Params` in init.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct InitParams {
    pub dims: [u32; 4],
    pub consts: [f32; 4],
    pub fluence: [f32; 4],
}
const _: () = assert!(size_of::<InitParams>() == 48);

/// Sweeps `light` with incident `fluence`; J gets the single scattering of the unscattered
/// light with anisotropy `a0 g`. Sets `light.injected` and returns the energy report's sums.
pub fn sweep(ctx: &GpuContext, light: &mut GpuLight, h: f32, fluence: Vec3, a0: f32, g: f32) -> Result<SweepSums, GpuError> {
    let dims = light.dims;
    let slab = dims.x as u64 * dims.y as u64;
    let columns = ctx.zeroed_storage("sweep columns", slab * 3 * 16)?;
    // accumulate::add_direct's clamp of the anisotropy.
    let a = (a0 * g).clamp(-0.9995, 0.9995);
    let params = InitParams { dims: [dims.x, dims.y, dims.z, 0], consts: [h, a, 0.0, 0.0], fluence: fluence.extend(0.0).to_array() };
    let params = ctx.uniform("init params", bytemuck::bytes_of(&params));
    let pipeline = ctx.pipeline("init.wgsl", WGSL, "main")?;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    ctx.record(
        &mut enc,
        &pipeline,
        &[&params, &light.sigma_s, &light.sigma_a, &light.mu, &light.packets, &light.j, &columns],
        [dims.x.div_ceil(8), dims.y.div_ceil(8), 1],
    );
    ctx.submit(enc);
    let cols = read_rgb(ctx, &columns, slab * 3)?;
    // init::sweep's sums over the columns that meet the medium.
    let mut sums = SweepSums::default();
    let mut injected = Vec3::ZERO;
    for c in cols.chunks_exact(3) {
        let (tau, absorbed, packets) = (c[0], c[1], c[2]);
        if tau.max_element() > 0.0 {
            sums.entering += fluence;
            sums.transmitted += fluence * (-tau).exp();
            sums.absorbed += absorbed;
        }
        injected += packets;
    }
    light.injected = injected;
    Ok(sums)
}

#[cfg(test)]
#[path = "init_tests.rs"]
mod tests;
