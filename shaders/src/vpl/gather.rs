//! The VPL gather on the GPU (`gather.wgsl`): the same gather points and connections as
//! `volscatter_core::solvers::vpl::gather::gather` (the plan, `GatherPlan`, is built on the CPU:
//! each point's density, view, kernel and subset), the connections, which are the gather's cost
//! (every point x every VPL of its subset, each a ray-marched transmittance), made on the GPU,
//! and each point finished on the CPU as there (`GatherPlan::finish`: reweighting, energy
//! report, and the bias compensation of `near_field: compensate`, which stays on the CPU).
//!
//! Transmittance: the GPU marches every connection, whatever `transmittance` says. `map` (the
//! CPU default, core's vpl/depth_map.rs) approximates this march to save the CPU's time; on
//! the GPU the march is the cheap part it was built for, and its result is the one the map
//! is measured against (default scene, 16384 walks: the same image error to 3e-5). Likewise
//! every VPL is connected, whatever `cluster_distance` says (the CPU's far-field clusters,
//! core's vpl/far_field.rs, are its way of affording the walks the GPU simply connects), and
//! the GPU's single-scattering grid marches the sky at every point (`dome_spacing` is the
//! CPU's).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rayon::prelude::*;
use std::mem::{offset_of, size_of};

use crate::context::{GpuContext, GpuError};
use crate::upload::{affine_rows, bricked_density_bytes};
use volscatter_core::medium::Medium;
use volscatter_core::stages::upsample::Merged;
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::solvers::vpl::compensate::{Compensation, Vertex};
use volscatter_core::solvers::vpl::gather::{GatherPlan, GatherPoint, Gathered, Kernel};
use volscatter_core::solvers::vpl::{GatherStats, VplSettings};
use volscatter_core::solvers::vpl::walks::Walks;
use volscatter_core::stages::Progress;
use volscatter_core::{Error, Result, Scene};

pub const WGSL: &str = crate::wgsl::kernel_wgsl!(["affine", "trilinear", "density", "ray_box", "hg", "optics"], "vpl/gather.wgsl");

/// Mirrors `struct Params` in gather.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GatherParams {
    pub density_w2i: [[f32; 4]; 3],
    pub density_brick_min: [i32; 4],
    pub density_brick_dims: [u32; 4],
    pub density_scale: [f32; 4],
    pub bounds_lo: [f32; 4],
    pub bounds_hi: [f32; 4],
    pub misc: [f32; 4],
    pub range: [u32; 4],
}
const _: () = {
    assert!(size_of::<GatherParams>() == 160);
    assert!(offset_of!(GatherParams, density_scale) == 80);
    assert!(offset_of!(GatherParams, range) == 144);
};

/// Mirrors `struct Point` in gather.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuPoint {
    pub position: [f32; 4],
    pub view: [f32; 4],
    pub list: [u32; 4],
    pub hat: [f32; 4],
}
const _: () = assert!(size_of::<GpuPoint>() == 64);

/// Mirrors `struct Vpl` in gather.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuVpl {
    pub position: [f32; 4],
    pub incident: [f32; 4],
    pub power: [f32; 4],
}
const _: () = assert!(size_of::<GpuVpl>() == 48);

/// Connections (point x VPL) per dispatch: the solve looks at cancellation between dispatches.
/// About 2^21 ray marches of tens of steps: tens of milliseconds on a large GPU.
const CONNECTIONS_PER_DISPATCH: u64 = 1 << 21;

/// Bytes of `out` per point in gather.wgsl: (sum, near), (lost, -), (iso, -).
const SUMS_BYTES: u64 = 48;

/// What `connect` returned for each point, with its count of near connections.
pub struct Connected {
    pub sum: Vec3,
    pub lost: Vec3,
    /// `sum` with the point's phase function replaced by 1 / 4 pi (`connect_iso`).
    pub iso: Vec3,
    pub near: u64,
}

/// `connect` (volscatter-core vpl/gather.rs) for every point on the GPU: `lists` the VPL lists
/// the points' `subset` index, `step` the transmittance march's step. Returns
/// `Error::Cancelled` between dispatches once `progress` is cancelled.
pub fn connect_points(ctx: &GpuContext, medium: &Medium, lists: &[Vec<volscatter_core::solvers::vpl::walks::Vpl>], points: &[GatherPoint], step: f32, progress: &dyn Progress) -> Result<Vec<Connected>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let to_gpu = |e: GpuError| -> Error { e.into() };
    let total_vpls: usize = lists.iter().map(Vec::len).sum();
    ctx.check_storage_size("vpl gather: VPLs", total_vpls as u64 * size_of::<GpuVpl>() as u64).map_err(to_gpu)?;
    ctx.check_storage_size("vpl gather: points", points.len() as u64 * size_of::<GpuPoint>() as u64).map_err(to_gpu)?;
    ctx.check_storage_size("vpl gather: sums", points.len() as u64 * SUMS_BYTES).map_err(to_gpu)?;
    ctx.check_storage_size("vpl gather: density", bricked_density_bytes(medium)).map_err(to_gpu)?;
    let mut starts = Vec::with_capacity(lists.len());
    let mut vpls = Vec::with_capacity(total_vpls);
    for list in lists {
        starts.push(vpls.len() as u32);
        vpls.extend(list.iter().map(|v| GpuVpl { position: v.position.extend(0.0).to_array(), incident: v.incident.extend(0.0).to_array(), power: v.power.extend(0.0).to_array() }));
    }
    let gpu_points: Vec<GpuPoint> = points
        .iter()
        .map(|p| {
            let (radius, kind, cone, hat) = match p.kernel {
                Kernel::Clamp(r) => (r, 0, 0.0f32, Vec3::ZERO),
                Kernel::Ball { radius, cone } => (radius, 1, cone, Vec3::ZERO),
                Kernel::Hat { radius, cone, inside } => (radius, 2, cone, inside),
            };
            let s = p.subset as usize;
            GpuPoint { position: p.position.extend(radius).to_array(), view: p.view.extend(p.ball).to_array(), list: [starts[s], lists[s].len() as u32, kind, cone.to_bits()], hat: hat.extend(0.0).to_array() }
        })
        .collect();
    let longest = lists.iter().map(Vec::len).max().unwrap_or(0) as u64;
    let n = points.len() as u64;
    // Workgroups: one per point, in rows of at most the adapter's limit.
    let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1) as u64;
    let per_row = n.min(max_groups);
    let rows = n.div_ceil(per_row);
    if rows > max_groups {
        return Err(GpuError::TooLarge(format!("vpl gather: {n} points")).into());
    }
    // VPLs per list per dispatch: a multiple of the workgroup's 64.
    let chunk = (CONNECTIONS_PER_DISPATCH / n).max(64).div_ceil(64) * 64;
    let density = crate::upload::resident_density(ctx, medium).map_err(to_gpu)?;
    let (lo, hi) = medium.world_bounds();
    let base = GatherParams {
        density_w2i: affine_rows(&medium.world_to_index),
        density_brick_min: density.brick_min,
        density_brick_dims: density.brick_dims,
        density_scale: medium.density_scale.extend(0.0).to_array(),
        bounds_lo: lo.extend(0.0).to_array(),
        bounds_hi: hi.extend(0.0).to_array(),
        misc: [medium.g, step, 0.0, 0.0],
        range: [0, chunk as u32, n as u32, per_row as u32],
    };
    let density: &wgpu::Buffer = &density.buffer;
    let point_buf = ctx.storage_buffer("vpl gather: points", bytemuck::cast_slice(&gpu_points)).map_err(to_gpu)?;
    let vpl_buf = ctx.storage_buffer("vpl gather: VPLs", bytemuck::cast_slice(&vpls)).map_err(to_gpu)?;
    let out = ctx.zeroed_storage("vpl gather: sums", n * SUMS_BYTES).map_err(to_gpu)?;
    let pipeline = ctx.pipeline("vpl/gather.wgsl", WGSL, "main").map_err(to_gpu)?;
    let mut first = 0u64;
    while first < longest {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let params = GatherParams { range: [first as u32, chunk as u32, n as u32, per_row as u32], ..base };
        let params = ctx.uniform("vpl gather params", bytemuck::bytes_of(&params));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        ctx.record(&mut enc, &pipeline, &[&params, density, &point_buf, &vpl_buf, &out], [per_row as u32, rows as u32, 1]);
        ctx.submit_and_wait(enc).map_err(to_gpu)?;
        first += chunk;
    }
    let bytes = ctx.read_buffer(&out, n * SUMS_BYTES).map_err(to_gpu)?;
    let sums: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    Ok(sums
        .chunks_exact(3)
        .map(|c| Connected { sum: Vec3::new(c[0][0], c[0][1], c[0][2]), lost: Vec3::new(c[1][0], c[1][1], c[1][2]), iso: Vec3::new(c[2][0], c[2][1], c[2][2]), near: c[0][3] as u64 })
        .collect())
}

/// `volscatter_core::solvers::vpl::gather::gather` with the connections on the GPU: the
/// gather points' to their subsets, then (`near_field: compensate`) the compensation vertices'
/// to theirs, all vertices sampled on the CPU first (`Compensation::vertices`).
pub fn gather(ctx: &GpuContext, scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<Gathered> {
    let plan = GatherPlan::new(scene, mip, walks, s)?;
    let [nx, ny, nz] = plan.grid.dims;
    let mut density = vec![0.0f32; plan.grid.len()];
    let mut points = Vec::new();
    for k in 0..nz {
        for jj in 0..ny {
            for i in 0..nx {
                let (rho, point) = plan.point(i, jj, k);
                density[(i + nx * (jj + ny * k)) as usize] = rho;
                points.extend(point);
            }
        }
    }
    let connected = connect_points(ctx, &scene.medium, &plan.lists, &points, plan.step, progress)?;
    let mut stats = GatherStats::default();
    let back = match plan.compensation() {
        Some(c) => Some(compensate(ctx, &plan, c, &points, progress, &mut stats)?),
        None => None,
    };
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    let mut j = plan.grid.clone();
    let mut iso = vec![Vec3::ZERO; j.len()];
    for (n, (p, c)) in points.iter().zip(&connected).enumerate() {
        iso[p.index as usize] = plan.reweight(c.iso);
        stats.connections += plan.lists[p.subset as usize].len() as u64;
        stats.near += c.near;
        j.data[p.index as usize] = plan.finish_with(p, c.sum, c.lost, back.as_ref().map(|b| b[n]), &mut stats);
    }
    Ok(Gathered { merged: Merged { j, density }, stats, iso })
}

/// The compensation's estimate at every point (`Compensation::estimate`), its connections on
/// the GPU: the vertices of all points sampled on the CPU (in parallel, each point its own
/// random numbers as on the CPU), connected in one batch, combined on the CPU.
fn compensate(ctx: &GpuContext, plan: &GatherPlan, c: &Compensation, points: &[GatherPoint], progress: &dyn Progress, stats: &mut GatherStats) -> Result<Vec<Vec3>> {
    let trees: Vec<(Vec<Vertex>, GatherStats)> = points
        .par_iter()
        .map(|p| {
            let mut st = GatherStats::default();
            if progress.cancelled() {
                return (Vec::new(), st);
            }
            let nodes = c.vertices(p.position, -p.view, &mut plan.compensation_rng(p), &mut st);
            (nodes, st)
        })
        .collect();
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    let queries: Vec<GatherPoint> = trees
        .iter()
        .flat_map(|(nodes, _)| nodes.iter())
        .map(|v| {
            let (kernel, ball) = c.kernel(v);
            GatherPoint { index: 0, position: v.position, view: v.view, rho: 0.0, kernel, ball, subset: v.list }
        })
        .collect();
    let connected = connect_points(ctx, plan.medium(), c.lists(), &queries, c.step(), progress)?;
    let mut at = 0;
    let mut back = Vec::with_capacity(points.len());
    for (nodes, st) in &trees {
        stats.add(st);
        let light: Vec<Vec3> = connected[at..at + nodes.len()].iter().map(|q| q.sum).collect();
        for (v, q) in nodes.iter().zip(&connected[at..at + nodes.len()]) {
            stats.connections += c.lists()[v.list as usize].len() as u64;
            stats.near += q.near;
        }
        back.push(c.combine(nodes, &light));
        at += nodes.len();
    }
    Ok(back)
}
