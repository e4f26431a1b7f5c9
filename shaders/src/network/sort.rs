//! A bitonic sort of u32 keys on the GPU (`sort.wgsl`): independent lists of a power-of-two
//! length, each ascending by (x, y, z, w) of its vec4<u32> keys. The visibility network sorts
//! each direction's (pixel, depth, particle) keys with it, the splat its (tile, particle) pairs.

use bytemuck::{Pod, Zeroable};
use std::mem::size_of;

use crate::context::GpuContext;
use volscatter_core::stages::Progress;
use volscatter_core::Error;

pub const WGSL: &str = include_str!("sort.wgsl");

/// Mirrors `struct Params` in sort.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SortParams {
    pub stage: [u32; 4],
    pub rows: [u32; 4],
}
const _: () = assert!(size_of::<SortParams>() == 32);

pub const GROUP: u32 = 64;
/// Workgroups per dispatch dimension that every adapter allows (WebGPU's minimum limit).
pub const MAX_GROUPS: u32 = 65535;
/// Compare-and-swaps per submission (entries x stages): ~2^24 keep a submission within tens
/// of ms on lavapipe, so that a cancel is seen between two.
const SWAPS_PER_SUBMIT: u64 = 1 << 24;

/// Workgroups (x, y) for one invocation per entry, and the invocations per dispatch row.
pub fn groups_for(entries: u32) -> ([u32; 3], u32) {
    let groups = entries.div_ceil(GROUP).max(1);
    let (gx, gy) = (groups.min(MAX_GROUPS), groups.div_ceil(MAX_GROUPS));
    ([gx, gy, 1], gx * GROUP)
}

/// Sorts `keys` (`lists` lists of `len` entries each, `len` a power of two) in place;
/// `Error::Cancelled` once `progress` is cancelled (looked at between submissions).
pub fn sort(ctx: &GpuContext, keys: &wgpu::Buffer, len: u32, lists: u32, progress: &dyn Progress) -> Result<(), Error> {
    debug_assert!(len.is_power_of_two());
    let entries = len.checked_mul(lists).ok_or_else(|| Error::Device("network sort: more than 2^32 keys".into()))?;
    let pipeline = ctx.pipeline("network/sort.wgsl", WGSL, "main")?;
    let (groups, row) = groups_for(entries);
    let per_submit = (SWAPS_PER_SUBMIT / entries as u64).max(1);
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    let mut recorded = 0u64;
    let mut k = 2u32;
    while k <= len {
        let mut j = k / 2;
        while j > 0 {
            let params = ctx.uniform("network sort params", bytemuck::bytes_of(&SortParams { stage: [k, j, len, entries], rows: [row, 0, 0, 0] }));
            ctx.record(&mut enc, &pipeline, &[&params, keys], groups);
            recorded += 1;
            if recorded.is_multiple_of(per_submit) {
                ctx.submit_and_wait(std::mem::replace(&mut enc, ctx.device.create_command_encoder(&Default::default())))?;
                if progress.cancelled() {
                    return Err(Error::Cancelled);
                }
            }
            j /= 2;
        }
        k *= 2;
    }
    ctx.submit_and_wait(enc)?;
    Ok(())
}
