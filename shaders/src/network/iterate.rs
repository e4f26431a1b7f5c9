//! The iteration of Eq. 2 on the GPU (core network/iterate.rs), three kernels per iteration:
//! `source.wgsl` (Q = E + a P I, a tiled matrix product), `sweep.wgsl` (one invocation per
//! column, in place, with the column's residual share) and `residual.wgsl` (the residual,
//! appended to a buffer, and a convergence flag that turns the rest of the batch into no-ops).
//! Iterations are recorded `check_every` at a time; between batches the host reads back two
//! words (flag and count) and looks at `progress.cancelled()`. The result is the CPU's, same
//! iterations and same stopping point, up to float32 rounding of the sums.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use crate::pop::light::read_rgb;
use crate::upload::rgb_as_vec4;
use volscatter_core::solvers::network::backend::IterationInput;
use volscatter_core::solvers::network::iterate::Iterated;
use volscatter_core::solvers::network::visibility::NONE;
use volscatter_core::stages::Progress;

pub const SOURCE_WGSL: &str = crate::wgsl::kernel_wgsl!(["network"], "network/source.wgsl");
pub const SWEEP_WGSL: &str = crate::wgsl::kernel_wgsl!(["network"], "network/sweep.wgsl");
pub const RESIDUAL_WGSL: &str = crate::wgsl::kernel_wgsl!(["network"], "network/residual.wgsl");

/// Mirrors `struct Params` in wgsl/network.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct IterateParams {
    pub counts: [u32; 4],
    pub albedo_threshold: [f32; 4],
}
const _: () = assert!(size_of::<IterateParams>() == 32);

const TILE: u32 = 16;
const SWEEP_GROUP: u32 = 64;
/// Workgroups per dispatch dimension that every adapter allows (WebGPU's minimum limit).
const MAX_GROUPS: u32 = 65535;

/// The links flattened for the sweep: per list entry (direction x N + position) the particle,
/// its upstream neighbour and the gap's opacity; per column its range of entries.
struct Lists {
    nodes: Vec<[u32; 2]>,
    alpha: Vec<[f32; 4]>,
    columns: Vec<[u32; 2]>,
}

/// Flattens `input.links`. A column is a run of the list that starts at a particle without an
/// upstream neighbour and in which each particle's neighbour is the one before it (what
/// visibility.rs builds); anything else cannot be swept one column per invocation and is
/// refused (the `auto` device then solves on the CPU).
fn flatten(input: &IterationInput, n: usize) -> Result<Lists, GpuError> {
    let d = input.links.len();
    let entries = n * d;
    if entries > u32::MAX as usize {
        return Err(GpuError::TooLarge(format!("{n} particles x {d} directions exceed 2^32 list entries")));
    }
    let mut lists = Lists { nodes: Vec::with_capacity(entries), alpha: Vec::with_capacity(entries), columns: Vec::new() };
    for l in input.links {
        if l.order.len() != n || l.up.len() != n || l.alpha.len() != n {
            return Err(GpuError::Internal("network links do not cover every particle".into()));
        }
        let mut prev = NONE;
        for &p in &l.order {
            let up = *l.up.get(p as usize).ok_or_else(|| GpuError::Internal("network link out of range".into()))?;
            let k = lists.nodes.len() as u32;
            if up == NONE {
                if let Some(last) = lists.columns.last_mut() {
                    last[1] = k;
                }
                lists.columns.push([k, k]);
            } else if up != prev || lists.columns.is_empty() {
                return Err(GpuError::Internal("network lists are not in column order".into()));
            }
            let a = l.alpha[p as usize];
            lists.nodes.push([p, up]);
            lists.alpha.push([a.x, a.y, a.z, 0.0]);
            prev = p;
        }
    }
    if let Some(last) = lists.columns.last_mut() {
        last[1] = lists.nodes.len() as u32;
    }
    Ok(lists)
}

/// Runs the iteration of `input` from `start` (or zero) on the GPU, reading back every
/// `check_every` iterations; stops early (returning what it has) once `progress` is cancelled.
pub fn iterate(ctx: &GpuContext, input: &IterationInput, start: Option<Vec<Vec3>>, check_every: u32, progress: &dyn Progress) -> Result<Iterated, GpuError> {
    let d = input.links.len();
    let n = input.first.len() / d.max(1);
    if d == 0 || n == 0 {
        return Ok(Iterated { radiance: vec![Vec3::ZERO; n * d], residuals: Vec::new() });
    }
    if input.phase.len() != d * d || input.first.len() != n * d {
        return Err(GpuError::Internal("network phase matrix or direct light of the wrong size".into()));
    }
    let pairs = (n * d) as u64;
    // Radiance, source, first and alpha (vec4 each) and nodes: check every size before the first allocation.
    for (what, bytes) in [("network radiance", pairs * 16), ("network list nodes", pairs * 8), ("network phase matrix", (d * d) as u64 * 4)] {
        ctx.check_storage_size(what, bytes)?;
    }
    let lists = flatten(input, n)?;
    let columns = lists.columns.len() as u32;
    let sweep_groups = columns.div_ceil(SWEEP_GROUP);
    let (gx, gy) = (sweep_groups.clamp(1, MAX_GROUPS), sweep_groups.div_ceil(MAX_GROUPS).max(1));
    let params = IterateParams {
        counts: [n as u32, d as u32, columns, gx * SWEEP_GROUP],
        albedo_threshold: [input.albedo.x, input.albedo.y, input.albedo.z, input.threshold],
    };
    let start = start.filter(|s| s.len() == n * d).unwrap_or_else(|| vec![Vec3::ZERO; n * d]);
    let params_buf = ctx.uniform("network params", bytemuck::bytes_of(&params));
    let state = ctx.zeroed_storage("network state", 8)?;
    let phase = ctx.storage_buffer("network phase", bytemuck::cast_slice(input.phase))?;
    let first = ctx.storage_buffer("network first scattering", bytemuck::cast_slice(&rgb_as_vec4(input.first)))?;
    let radiance = ctx.storage_buffer("network radiance", bytemuck::cast_slice(&rgb_as_vec4(&start)))?;
    drop(start);
    let source = ctx.zeroed_storage("network source", pairs * 16)?;
    let column_buf = ctx.storage_buffer("network columns", bytemuck::cast_slice(&lists.columns))?;
    let nodes = ctx.storage_buffer("network list nodes", bytemuck::cast_slice(&lists.nodes))?;
    let alpha = ctx.storage_buffer("network opacities", bytemuck::cast_slice(&lists.alpha))?;
    drop(lists);
    let partial = ctx.zeroed_storage("network residual shares", columns as u64 * 8)?;
    let residuals = ctx.zeroed_storage("network residuals", input.max_iterations as u64 * 4)?;
    let source_k = ctx.pipeline("network/source.wgsl", SOURCE_WGSL, "main")?;
    let sweep_k = ctx.pipeline("network/sweep.wgsl", SWEEP_WGSL, "main")?;
    let residual_k = ctx.pipeline("network/residual.wgsl", RESIDUAL_WGSL, "main")?;
    // A batch's source products cost N D^2 multiply-adds per iteration: at most ~2^31 of
    // them between two looks at cancellation (tens of ms on a current GPU; one iteration per
    // batch at the largest settings).
    let per_batch = check_every.clamp(1, ((1u64 << 31) / (pairs * d as u64)).clamp(1, u32::MAX as u64) as u32);
    let (mut recorded, mut count) = (0u32, 0u32);
    while recorded < input.max_iterations && !progress.cancelled() {
        let batch = per_batch.min(input.max_iterations - recorded);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        for _ in 0..batch {
            ctx.record(&mut enc, &source_k, &[&params_buf, &state, &phase, &first, &radiance, &source], [(d as u32).div_ceil(TILE), (n as u32).div_ceil(TILE), 1]);
            ctx.record(&mut enc, &sweep_k, &[&params_buf, &state, &column_buf, &nodes, &alpha, &source, &radiance, &partial], [gx, gy, 1]);
            ctx.record(&mut enc, &residual_k, &[&params_buf, &state, &partial, &residuals], [1, 1, 1]);
        }
        ctx.submit_and_wait(enc)?;
        recorded += batch;
        let words = ctx.read_buffer(&state, 8)?;
        let [done, iterations]: [u32; 2] = bytemuck::pod_read_unaligned(&words);
        count = iterations;
        if done != 0 {
            break;
        }
    }
    let residuals = if count > 0 { ctx.read_buffer(&residuals, count as u64 * 4)? } else { Vec::new() };
    Ok(Iterated {
        radiance: read_rgb(ctx, &radiance, pairs)?,
        residuals: bytemuck::cast_slice::<u8, f32>(&residuals).iter().map(|&r| r as f64).collect(),
    })
}

#[cfg(test)]
#[path = "iterate_tests.rs"]
pub(crate) mod tests;
