//! Merging the lights' accumulation grids on the GPU (`merge.wgsl`): same inputs and outputs
//! as `volscatter_core::solvers::pop::merge::merge`, with every light's J read where it lies in
//! device memory and the merged grid left there for the upsampling.

use bytemuck::{Pod, Zeroable};
use std::mem::{offset_of, size_of};

use crate::context::{GpuContext, GpuError};
use crate::pop::light::read_rgb;
use crate::pop::mip::{GpuMip, MipParams};
use crate::upload::{affine_rows, rgb_as_vec4};
use volscatter_core::medium::Medium;
use volscatter_core::solvers::pop::light_grid::LightGrid;
use volscatter_core::stages::upsample::{footprint, Merged};
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::ScatteringGrid;

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "mip", "j_grid"], "pop/merge.wgsl");

/// Mirrors `struct Params` in merge.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct MergeParams {
    pub merged_i2w: [[f32; 4]; 3],
    pub light_w2i: [[f32; 4]; 3],
    pub density_w2i: [[f32; 4]; 3],
    pub merged_dims: [u32; 4],
    pub light_dims: [i32; 4],
    pub mip: MipParams,
}
const _: () = {
    assert!(size_of::<MergeParams>() == 304);
    assert!(offset_of!(MergeParams, merged_dims) == 144);
    assert!(offset_of!(MergeParams, mip) == 176);
};

/// The merged grid in device memory.
pub struct GpuMerged {
    /// Dims and frame of the merged grid (its `data` is left empty: J lives in `j`).
    pub grid: ScatteringGrid,
    pub j: crate::context::Buf,
    pub density: crate::context::Buf,
    /// One u32: the bits of the largest density (see merge.wgsl).
    pub max_density: crate::context::Buf,
}

impl GpuMerged {
    fn points(&self) -> u64 {
        self.grid.dims.iter().map(|&d| d as u64).product()
    }

    /// A CPU merge result in device memory (to test the upsampling on the CPU's inputs).
    pub fn upload(ctx: &GpuContext, merged: &Merged) -> Result<Self, GpuError> {
        let max = merged.density.iter().fold(0.0f32, |m, &v| m.max(v));
        let grid = ScatteringGrid { dims: merged.j.dims, index_to_world: merged.j.index_to_world, data: Vec::new() };
        Ok(GpuMerged {
            grid,
            j: ctx.storage_buffer("merged j", bytemuck::cast_slice(&rgb_as_vec4(&merged.j.data)))?,
            density: ctx.storage_buffer("merged density", bytemuck::cast_slice(&merged.density))?,
            max_density: ctx.storage_buffer("max density", bytemuck::bytes_of(&[max.to_bits(), 0, 0, 0]))?,
        })
    }

    /// Read back as the CPU's `Merged` (tests).
    pub fn read(&self, ctx: &GpuContext) -> Result<Merged, GpuError> {
        let n = self.points();
        let mut j = self.grid.clone();
        j.data = read_rgb(ctx, &self.j, n)?;
        let density = bytemuck::cast_slice::<u8, f32>(&ctx.read_buffer(&self.density, n * 4)?).to_vec();
        Ok(Merged { j, density })
    }
}

/// `lights`: each light's grid and its J buffer, summed in this order.
pub fn merge(ctx: &GpuContext, gmip: &GpuMip, medium: &Medium, mip: &MediumMip, lights: &[(&LightGrid, &wgpu::Buffer)], resolution: u32) -> Result<GpuMerged, GpuError> {
    let grid = ScatteringGrid::over_medium(medium, resolution).map_err(|e| GpuError::TooLarge(e.to_string()))?;
    let n = grid.data.len() as u64;
    let fp = footprint(medium, &grid);
    let merged = GpuMerged {
        j: ctx.zeroed_storage("merged j", n * 16)?,
        density: ctx.zeroed_storage("merged density", n * 4)?,
        max_density: ctx.zeroed_storage("max density", 16)?,
        grid: ScatteringGrid { data: Vec::new(), ..grid },
    };
    let d = merged.grid.dims;
    let pipeline = ctx.pipeline("merge.wgsl", WGSL, "main")?;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let no_light = ctx.zeroed_storage("no light", 16)?;
    // With no light at all, one pass still writes the density guide.
    let passes: Vec<Option<&(&LightGrid, &wgpu::Buffer)>> = if lights.is_empty() { vec![None] } else { lights.iter().map(Some).collect() };
    for (k, light) in passes.into_iter().enumerate() {
        let (light_w2i, light_dims, j) = match light {
            Some((g, j)) => (affine_rows(&g.world_to_index), [g.dims.x as i32, g.dims.y as i32, g.dims.z as i32, 1], *j),
            None => (affine_rows(&glam::Affine3A::IDENTITY), [1, 1, 1, 0], &*no_light),
        };
        let params = MergeParams {
            merged_i2w: affine_rows(&merged.grid.index_to_world),
            light_w2i,
            density_w2i: affine_rows(&medium.world_to_index),
            merged_dims: [d[0], d[1], d[2], (k == 0) as u32],
            light_dims,
            mip: gmip.at_footprint(mip, fp),
        };
        let params = ctx.uniform("merge params", bytemuck::bytes_of(&params));
        ctx.record(
            &mut enc,
            &pipeline,
            &[&params, &gmip.buffer, j, &merged.j, &merged.density, &merged.max_density],
            [d[0].div_ceil(4), d[1].div_ceil(4), d[2].div_ceil(4)],
        );
    }
    ctx.submit_and_wait(enc)?;
    Ok(merged)
}

#[cfg(test)]
#[path = "merge_tests.rs"]
mod tests;
