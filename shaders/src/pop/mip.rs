//! The density's mip pyramid in device memory, uploaded once per solve and read by the merge
//! and upsampling kernels through `mip.wgsl` (a port of `MediumMip::sample`).

use bytemuck::{Pod, Zeroable};
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use volscatter_core::solvers::pop::mip::MediumMip;

/// The shared density lookup, prepended to the kernels that use it (WGSL has no includes).
pub const WGSL: &str = include_str!("mip.wgsl");

/// Mirrors `struct MipLevel` in mip.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
pub struct MipLevel {
    /// Cells per axis; w = offset of the level's cell 0 in the buffer.
    pub dims: [i32; 4],
    /// Voxels per cell.
    pub scale: [f32; 4],
}

/// The `mip_*` fields that end the parameters of every kernel including mip.wgsl (same order
/// and types there).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
pub struct MipParams {
    pub origin: [i32; 4],
    pub a: MipLevel,
    pub b: MipLevel,
    /// Weight of `b`; 1 in y when `b` is read at all.
    pub blend: [f32; 4],
}
const _: () = assert!(size_of::<MipParams>() == 96);

pub struct GpuMip {
    pub buffer: wgpu::Buffer,
    origin: [i32; 4],
    levels: Vec<MipLevel>,
}

impl GpuMip {
    /// All levels in one buffer, finest first.
    pub fn upload(ctx: &GpuContext, mip: &MediumMip) -> Result<Self, GpuError> {
        let total: u64 = mip.levels().map(|(_, _, data)| data.len() as u64).sum();
        ctx.check_storage_size("density mip", total * 4)?;
        if total > i32::MAX as u64 {
            return Err(GpuError::TooLarge(format!("density mip of {total} cells")));
        }
        let mut values = Vec::with_capacity(total as usize);
        let mut levels = Vec::new();
        for (dims, factor, data) in mip.levels() {
            levels.push(MipLevel { dims: [dims.x, dims.y, dims.z, values.len() as i32], scale: [factor as f32, 0.0, 0.0, 0.0] });
            values.extend_from_slice(data);
        }
        let o = mip.origin();
        Ok(GpuMip { buffer: ctx.storage_buffer("density mip", bytemuck::cast_slice(&values))?, origin: [o.x, o.y, o.z, 0], levels })
    }

    /// What `MediumMip::sample` reads at `footprint`. Where the CPU reads the density grid
    /// itself (footprint <= 1 with a full-resolution level 0), level 0 holds the same voxels.
    pub fn at_footprint(&self, mip: &MediumMip, footprint: f32) -> MipParams {
        let (l0, l1, t) = mip.blend(footprint).unwrap_or((0, 0, 0.0));
        let second = !(t == 0.0 || l1 == l0);
        MipParams { origin: self.origin, a: self.levels[l0], b: self.levels[l1], blend: [t, second as u32 as f32, 0.0, 0.0] }
    }
}
