//! Totals of per-cell fields without reading the grid back (`sum.wgsl`): per-column sums on the
//! GPU, one slab read back and added on the host.

use bytemuck::{Pod, Zeroable};
use glam::{UVec3, Vec3};
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use crate::pop::light::read_rgb;

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["columns"], "pop/sum.wgsl");

/// Mirrors `struct Params` in sum.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SumParams {
    pub dims: [u32; 4],
    pub stride_offset: [u32; 4],
}
const _: () = assert!(size_of::<SumParams>() == 32);

/// Sum over the cells of a grid of `dims` of the vec4 at `offset` of each cell's `stride`.
pub fn total(ctx: &GpuContext, field: &wgpu::Buffer, dims: UVec3, stride: u32, offset: u32) -> Result<Vec3, GpuError> {
    let slab = dims.x as u64 * dims.y as u64;
    let sums = ctx.zeroed_storage("column sums", slab * 16)?;
    let params = ctx.uniform("sum params", bytemuck::bytes_of(&SumParams { dims: [dims.x, dims.y, dims.z, 0], stride_offset: [stride, offset, 0, 0] }));
    let pipeline = ctx.pipeline("sum.wgsl", WGSL, "main")?;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    ctx.record(&mut enc, &pipeline, &[&params, field, &sums], [dims.x.div_ceil(8), dims.y.div_ceil(8), 1]);
    ctx.submit(enc);
    Ok(read_rgb(ctx, &sums, slab)?.into_iter().sum())
}
