//! Joint bilateral upsampling on the GPU (`upsample.wgsl`): same inputs and output as
//! `volscatter_core::stages::upsample::upsample`, reading the merged grid where the merge
//! left it; the scattering grid S is the one thing a GPU solve reads back.

use bytemuck::{Pod, Zeroable};
use std::mem::{offset_of, size_of};

use crate::context::{GpuContext, GpuError};
use crate::pop::light::read_rgb;
use crate::pop::merge::GpuMerged;
use crate::pop::mip::{GpuMip, MipParams};
use crate::upload::affine_rows;
use volscatter_core::medium::Medium;
use volscatter_core::stages::upsample::footprint;
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::stages::upsample::Upsampling;
use volscatter_core::ScatteringGrid;

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "mip", "j_grid"], "pop/upsample.wgsl");

/// Mirrors `struct Params` in upsample.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct UpsampleParams {
    pub out_i2w: [[f32; 4]; 3],
    pub to_coarse: [[f32; 4]; 3],
    pub density_w2i: [[f32; 4]; 3],
    pub out_dims: [u32; 4],
    pub coarse_dims: [i32; 4],
    pub bilateral: [f32; 4],
    pub sigma_s_per_density: [f32; 4],
    pub mip: MipParams,
}
const _: () = {
    assert!(size_of::<UpsampleParams>() == 336);
    assert!(offset_of!(UpsampleParams, out_dims) == 144);
    assert!(offset_of!(UpsampleParams, mip) == 208);
};

pub fn upsample(
    ctx: &GpuContext,
    gmip: &GpuMip,
    medium: &Medium,
    mip: &MediumMip,
    merged: &GpuMerged,
    settings: &Upsampling,
) -> Result<ScatteringGrid, GpuError> {
    let mut out = ScatteringGrid::over_medium(medium, settings.output_resolution).map_err(|e| GpuError::TooLarge(e.to_string()))?;
    let n = out.data.len() as u64;
    let fp = footprint(medium, &out);
    let coarse = &merged.grid;
    let cd = coarse.dims;
    // The CPU's constants, computed the same way.
    let inv_spatial = 1.0 / (2.0 * settings.spatial_sigma * settings.spatial_sigma);
    let radius = (2.0 * settings.spatial_sigma).ceil().max(1.0);
    let params = UpsampleParams {
        out_i2w: affine_rows(&out.index_to_world),
        to_coarse: affine_rows(&coarse.index_to_world.inverse()),
        density_w2i: affine_rows(&medium.world_to_index),
        out_dims: [out.dims[0], out.dims[1], out.dims[2], 0],
        coarse_dims: [cd[0] as i32, cd[1] as i32, cd[2] as i32, settings.upsample as i32],
        bilateral: [settings.range_sigma, inv_spatial, radius, 0.0],
        sigma_s_per_density: (medium.albedo * medium.density_scale).extend(0.0).to_array(),
        mip: gmip.at_footprint(mip, fp),
    };
    let params = ctx.uniform("upsample params", bytemuck::bytes_of(&params));
    let s = ctx.zeroed_storage("scattering grid", n * 16)?;
    let pipeline = ctx.pipeline("upsample.wgsl", WGSL, "main")?;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    ctx.record(
        &mut enc,
        &pipeline,
        &[&params, &gmip.buffer, &merged.j, &merged.density, &merged.max_density, &s],
        [out.dims[0].div_ceil(4), out.dims[1].div_ceil(4), out.dims[2].div_ceil(4)],
    );
    ctx.submit_and_wait(enc)?;
    out.data = read_rgb(ctx, &s, n)?;
    Ok(out)
}

#[cfg(test)]
#[path = "upsample_tests.rs"]
mod tests;
