//! One light's data in device memory, from the transmittance sweep to the merge: uploaded once
//! (the grid's coefficients and view cosines), then written and read only by kernels.

use glam::{UVec3, Vec3};

use crate::context::{GpuContext, GpuError};
use crate::upload::rgb_as_vec4;
use volscatter_core::solvers::pop::light_grid::LightGrid;

pub struct GpuLight {
    pub dims: UVec3,
    pub sigma_s: crate::context::Buf,
    pub sigma_a: crate::context::Buf,
    /// Cosine to the camera per cell (accumulate::view_cosines).
    pub mu: crate::context::Buf,
    /// The packets still to propagate; the sweep writes them, the propagation consumes them.
    pub packets: crate::context::Buf,
    /// The accumulation grid J, one vec4 per cell.
    pub j: crate::context::Buf,
    /// Energy injected into the propagation (the packets' sum), for its stopping threshold.
    pub injected: Vec3,
}

impl GpuLight {
    pub fn cells(&self) -> u64 {
        self.dims.x as u64 * self.dims.y as u64 * self.dims.z as u64
    }

    /// Uploads `grid`'s coefficients and `mu`; packets and J start at zero.
    pub fn upload(ctx: &GpuContext, grid: &LightGrid, mu: &[f32]) -> Result<Self, GpuError> {
        let cell_bytes = grid.len() as u64 * 16;
        Ok(GpuLight {
            dims: grid.dims,
            sigma_s: ctx.storage_buffer("sigma_s", bytemuck::cast_slice(&rgb_as_vec4(&grid.sigma_s)))?,
            sigma_a: ctx.storage_buffer("sigma_a", bytemuck::cast_slice(&rgb_as_vec4(&grid.sigma_a)))?,
            mu: ctx.storage_buffer("mu", bytemuck::cast_slice(mu))?,
            packets: ctx.zeroed_storage("packets", cell_bytes)?,
            j: ctx.zeroed_storage("j", cell_bytes)?,
            injected: Vec3::ZERO,
        })
    }

    /// J read back (tests, and the CPU fallback of options the GPU lacks).
    pub fn read_j(&self, ctx: &GpuContext) -> Result<Vec<Vec3>, GpuError> {
        read_rgb(ctx, &self.j, self.cells())
    }

    pub fn read_packets(&self, ctx: &GpuContext) -> Result<Vec<Vec3>, GpuError> {
        read_rgb(ctx, &self.packets, self.cells())
    }
}

/// `count` vec4s of a buffer as RGB.
pub fn read_rgb(ctx: &GpuContext, buf: &wgpu::Buffer, count: u64) -> Result<Vec<Vec3>, GpuError> {
    let bytes = ctx.read_buffer(buf, count * 16)?;
    Ok(bytemuck::cast_slice::<u8, [f32; 4]>(&bytes).iter().map(|v| Vec3::new(v[0], v[1], v[2])).collect())
}
