//! lpm's sweeps on the GPU: `GpuSweeps` implements volscatter-core's `SweepBackend` with two
//! kernels per slab of a face, propagate.wgsl (one workgroup per tile of rays and direction,
//! plane by plane) and collect.wgsl (one invocation per cell). The host keeps U and J, as the
//! CPU does, and streams each slab through the device (Sec. 4.2): it packs the slab's sigma_t
//! and U of the previous order in the face's frame, uploads them, and adds the slab's share of
//! U and J that it reads back, face after face in the CPU's order. Device memory is the maps of
//! one face (two copies: rays leave a slab into the other) plus one slab's buffers, each
//! within the adapter's largest storage binding: the slab thickness is the CPU's plan (from
//! `memory_budget`) or less where the adapter needs it.

use std::sync::Arc;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rayon::prelude::*;
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use volscatter_core::stages::diff::Bits;
use crate::pop::light::read_rgb;
use volscatter_core::solvers::lpm::directions::FACES;
use volscatter_core::solvers::lpm::propagate::FaceFrame;
use volscatter_core::solvers::lpm::stream::{SweepBackend, SweepSetup, SweepStats, Sweeper};
use volscatter_core::stages::Progress;
use volscatter_core::{Error, Result};

pub const PROPAGATE_WGSL: &str = crate::wgsl::kernel_wgsl!(["lpm"], "lpm/propagate.wgsl");
pub const COLLECT_WGSL: &str = crate::wgsl::kernel_wgsl!(["lpm"], "lpm/collect.wgsl");

/// Invocations per workgroup along x in both kernels (`@workgroup_size(64, 1, 1)`).
const TILE: u32 = 64;

/// Mirrors `struct Params` in wgsl/lpm.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct LpmParams {
    pub map: [u32; 4],
    pub sweep: [u32; 4],
    pub dirs: [u32; 4],
    pub albedo: [f32; 4],
}
const _: () = assert!(size_of::<LpmParams>() == 64);

/// Mirrors `struct Dir` in lpm/propagate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct GpuDir {
    pub boundary: [f32; 4],
    pub dl: f32,
    pub storage: u32,
    pub pad: [u32; 2],
}
const _: () = assert!(size_of::<GpuDir>() == 32);

/// The GPU backend of lpm's sweeps on `ctx`.
pub struct GpuSweeps {
    ctx: Arc<GpuContext>,
}

impl GpuSweeps {
    pub fn new(ctx: &Arc<GpuContext>) -> Self {
        GpuSweeps { ctx: ctx.clone() }
    }
}

impl SweepBackend for GpuSweeps {
    fn start<'a>(&'a self, setup: SweepSetup<'a>, progress: &dyn Progress) -> Result<Box<dyn Sweeper + 'a>> {
        // Between sweepers nothing is pending: the last one's buffers serve this one.
        self.ctx.idle();
        Ok(Box::new(GpuSweeper::new(&self.ctx, setup, progress)?))
    }
}

/// Slab thickness of each face on this adapter: `planned` (the CPU's plan from
/// `memory_budget`) or thinner, so that T (p values a cell) and U in and out (m a cell) fit
/// one storage binding, and a slab's layers one dispatch dimension. Refused (the `auto`
/// device then solves on the CPU) when one layer does not fit.
pub fn gpu_layers(ctx: &GpuContext, dims: [usize; 3], p: usize, m: usize, planned: &[usize; FACES]) -> Result<[usize; FACES], GpuError> {
    let max_bytes = (ctx.limits.max_storage_buffer_binding_size as u64).min(ctx.limits.max_buffer_size);
    let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1) as u64;
    let mut layers = [0usize; FACES];
    for (f, l) in layers.iter_mut().enumerate() {
        let ff = FaceFrame::from_dims(dims, f);
        let per_layer = ff.map_len() as u64 * 16 * p.max(m) as u64;
        let fit = max_bytes / per_layer.max(1);
        let tiles = (ff.map_len() as u64).div_ceil(TILE as u64);
        if fit == 0 || tiles > max_groups || p as u64 > max_groups {
            return Err(GpuError::TooLarge(format!(
                "lpm: one layer of {}x{} cells with {p} directions and {m} storage bins needs {} MiB per buffer and {tiles} workgroups, the adapter allows {} MiB and {max_groups}",
                ff.nu,
                ff.nv,
                per_layer >> 20,
                max_bytes >> 20
            )));
        }
        *l = planned[f].clamp(1, ff.nw.max(1)).min(fit.min(max_groups) as usize);
    }
    Ok(layers)
}

/// Device buffers and host staging of a solve's sweeps.
struct GpuSweeper<'a> {
    ctx: &'a GpuContext,
    setup: SweepSetup<'a>,
    layers: [usize; FACES],
    /// Each cell's bin towards the camera, in grid order (collect.rs computes it per cell).
    view_bins: Vec<u32>,
    dirs: crate::context::Buf,
    offsets: crate::context::Buf,
    by_incoming: crate::context::Buf,
    fine: crate::context::Buf,
    sigma: crate::context::Buf,
    u_in: crate::context::Buf,
    view_slab: crate::context::Buf,
    maps: [crate::context::Buf; 2],
    t: crate::context::Buf,
    u_out: crate::context::Buf,
    j_out: crate::context::Buf,
    device_bytes: u64,
    /// The exact bits of the grid's extinction: a face swept in one slab keeps its packed
    /// sigma_t on the device under this key (`GpuContext::resident`), uploaded once a session.
    sigma_key: u64,
}

/// One resident sigma_t slab per face (labels of `GpuContext::resident`).
const SIGMA_FACES: [&str; FACES] = ["lpm sigma_t face 0", "lpm sigma_t face 1", "lpm sigma_t face 2", "lpm sigma_t face 3", "lpm sigma_t face 4", "lpm sigma_t face 5"];

impl<'a> GpuSweeper<'a> {
    fn new(ctx: &'a GpuContext, setup: SweepSetup<'a>, progress: &dyn Progress) -> Result<Self> {
        let SweepSetup { grid, dirs, table, .. } = setup;
        let (p, m, n) = (dirs.per_face(), table.m, table.n);
        let layers = gpu_layers(ctx, grid.dims, p, m, setup.layers)?;
        let (mut map_cells, mut slab_cells) = (0u64, 0u64);
        for (f, &l) in layers.iter().enumerate() {
            let ff = FaceFrame::new(grid, f);
            map_cells = map_cells.max(ff.map_len() as u64);
            slab_cells = slab_cells.max(ff.map_len() as u64 * l as u64);
        }
        // Every ray's position at every layer, start + round(a w): Rust's rounding (half away
        // from zero) on the host, so that the GPU's rays visit the CPU's cells.
        let stride = grid.dims.iter().copied().max().unwrap_or(1);
        let offsets: Vec<[i32; 2]> =
            dirs.dirs.iter().flat_map(|d| (0..stride).map(move |w| [(d.a * w as f32).round() as i32, (d.b * w as f32).round() as i32])).collect();
        let by_incoming: Vec<f32> = (0..n).flat_map(|i| (0..m).map(move |d| table.storage[d * n + i])).collect();
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let camera = setup.camera;
        let view_bins: Vec<u32> = (0..grid.len())
            .into_par_iter()
            .map(|idx| {
                let [nx, ny, _] = grid.dims;
                let c = [idx % nx, (idx / nx) % ny, idx / (nx * ny)];
                dirs.view_index((camera - grid.centre(c)).normalize_or(Vec3::Z)) as u32
            })
            .collect();
        let v4 = 16u64;
        let sweeper = GpuSweeper {
            ctx,
            setup,
            layers,
            view_bins,
            dirs: ctx.zeroed_storage("lpm directions", n as u64 * size_of::<GpuDir>() as u64)?,
            offsets: ctx.storage_buffer("lpm ray offsets", bytemuck::cast_slice(&offsets))?,
            by_incoming: ctx.storage_buffer("lpm storage table", bytemuck::cast_slice(&by_incoming))?,
            fine: ctx.storage_buffer("lpm phase table", bytemuck::cast_slice(&table.view_table()))?,
            sigma: ctx.zeroed_storage("lpm slab sigma_t", slab_cells * v4)?,
            u_in: ctx.zeroed_storage("lpm slab U in", slab_cells * m as u64 * v4)?,
            view_slab: ctx.zeroed_storage("lpm slab view bins", slab_cells * 4)?,
            maps: [ctx.zeroed_storage("lpm maps", p as u64 * map_cells * v4)?, ctx.zeroed_storage("lpm maps", p as u64 * map_cells * v4)?],
            t: ctx.zeroed_storage("lpm slab T", p as u64 * slab_cells * v4)?,
            u_out: ctx.zeroed_storage("lpm slab U out", slab_cells * m as u64 * v4)?,
            j_out: ctx.zeroed_storage("lpm slab J", slab_cells * v4)?,
            device_bytes: (2 * p as u64 * map_cells + (p as u64 + 2 * m as u64 + 2) * slab_cells) * v4 + slab_cells * 4,
            sigma_key: Bits::new().debug(&grid.dims).f32s(grid.sigma_t.iter().flat_map(|v| v.to_array())).finish(),
        };
        ctx.check()?;
        Ok(sweeper)
    }
}

/// For every cell of the slab `w0..w1` of face `ff` (in the grid's planes `z`, each cell
/// once): (its index in the grid, its index in the slab's packed layout).
fn slab_cells(grid_dims: [usize; 3], ff: &FaceFrame, w0: usize, w1: usize, z: usize, mut f: impl FnMut(usize, usize)) {
    let [nx, ny, _] = grid_dims;
    let (a0, a1) = if ff.forward { (w0, w1) } else { (ff.nw - w1, ff.nw - w0) };
    let range = |axis: usize, n: usize| if axis == ff.axes.2 { a0..a1 } else { 0..n };
    if !range(2, grid_dims[2]).contains(&z) {
        return;
    }
    for y in range(1, ny) {
        for x in range(0, nx) {
            let c = [x, y, z];
            let (u, v, wg) = (c[ff.axes.0], c[ff.axes.1], c[ff.axes.2]);
            let w = if ff.forward { wg } else { ff.nw - 1 - wg } - w0;
            f(x + nx * (y + ny * z), w * ff.map_len() + v * ff.nu + u);
        }
    }
}

impl Sweeper for GpuSweeper<'_> {
    fn sweep(&mut self, u_prev: &[Vec3], boundary: &[Vec3], u_cur: &mut [Vec3], mut j: Option<&mut [Vec3]>, stats: &mut SweepStats, progress: &dyn Progress) -> Result<()> {
        let ctx = &*self.ctx;
        let SweepSetup { grid, dirs, table, albedo, .. } = self.setup;
        let (p, m, n) = (dirs.per_face(), table.m, table.n);
        let stride = grid.dims.iter().copied().max().unwrap_or(1) as u32;
        let plane = grid.dims[0] * grid.dims[1];
        stats.peak_working_bytes = stats.peak_working_bytes.max(self.device_bytes);
        let gpu_dirs: Vec<GpuDir> = dirs
            .dirs
            .iter()
            .zip(boundary)
            .map(|(d, b)| GpuDir { boundary: [b.x, b.y, b.z, 0.0], dl: grid.h * (1.0 + d.a * d.a + d.b * d.b).sqrt(), storage: d.storage as u32, pad: [0; 2] })
            .collect();
        ctx.write(&self.dirs, 0, bytemuck::cast_slice(&gpu_dirs));
        let propagate = ctx.pipeline("lpm/propagate.wgsl", PROPAGATE_WGSL, "main")?;
        let collect = ctx.pipeline("lpm/collect.wgsl", COLLECT_WGSL, "main")?;
        let mut sigma = Vec::new();
        let mut u_in = Vec::new();
        let mut view = Vec::new();
        for (f, &s) in self.layers.iter().enumerate() {
            let ff = FaceFrame::new(grid, f);
            let map_len = ff.map_len();
            let mut cur = 0;
            let mut w0 = 0;
            while w0 < ff.nw {
                let w1 = (w0 + s).min(ff.nw);
                let slab = (w1 - w0) * map_len;
                // Pack the slab's inputs in the face's frame.
                sigma.resize(slab, [0.0f32; 4]);
                u_in.resize(slab * m, [0.0f32; 4]);
                view.resize(slab, 0u32);
                // A face swept in one slab reads the same sigma_t every sweep and frame: kept
                // on the device (a face streamed in several slabs uploads each slab's).
                let whole = w0 == 0 && w1 == ff.nw;
                let resident = if whole {
                    let key = Bits::new().u64(self.sigma_key).u64(f as u64).finish();
                    Some(ctx.resident(SIGMA_FACES[f], key, || {
                        let mut packed = vec![[0.0f32; 4]; slab];
                        for z in 0..grid.dims[2] {
                            slab_cells(grid.dims, &ff, w0, w1, z, |idx, k| {
                                let st = grid.sigma_t[idx];
                                packed[k] = [st.x, st.y, st.z, 0.0];
                            });
                        }
                        ctx.storage_buffer(SIGMA_FACES[f], bytemuck::cast_slice(&packed))
                    })?)
                } else {
                    None
                };
                for z in 0..grid.dims[2] {
                    slab_cells(grid.dims, &ff, w0, w1, z, |idx, k| {
                        if !whole {
                            let st = grid.sigma_t[idx];
                            sigma[k] = [st.x, st.y, st.z, 0.0];
                        }
                        for d in 0..m {
                            let v = u_prev[idx * m + d];
                            u_in[k * m + d] = [v.x, v.y, v.z, 0.0];
                        }
                        view[k] = self.view_bins[idx];
                    });
                }
                if !whole {
                    ctx.write(&self.sigma, 0, bytemuck::cast_slice(&sigma));
                }
                let sigma_buf: &wgpu::Buffer = match &resident {
                    Some(b) => b,
                    None => &self.sigma,
                };
                ctx.write(&self.u_in, 0, bytemuck::cast_slice(&u_in));
                if j.is_some() {
                    ctx.write(&self.view_slab, 0, bytemuck::cast_slice(&view));
                }
                let params = LpmParams {
                    map: [ff.nu as u32, ff.nv as u32, map_len as u32, slab as u32],
                    sweep: [w0 as u32, w1 as u32, p as u32, m as u32],
                    dirs: [n as u32, (f * p) as u32, j.is_some() as u32, stride],
                    albedo: [albedo.x, albedo.y, albedo.z, 0.0],
                };
                let params = ctx.uniform("lpm params", bytemuck::bytes_of(&params));
                let tiles = (map_len as u32).div_ceil(TILE);
                let (map_in, map_out) = (&self.maps[cur], &self.maps[1 - cur]);
                let mut enc = ctx.device.create_command_encoder(&Default::default());
                ctx.record(&mut enc, &propagate, &[&params, &self.dirs, &self.offsets, sigma_buf, &self.u_in, map_in, map_out, &self.t], [tiles, p as u32, 1]);
                ctx.record(
                    &mut enc,
                    &collect,
                    &[&params, sigma_buf, &self.t, &self.by_incoming, &self.fine, &self.view_slab, &self.u_out, &self.j_out],
                    [tiles, (w1 - w0) as u32, 1],
                );
                ctx.submit_and_wait(enc)?;
                if progress.cancelled() {
                    return Err(Error::Cancelled);
                }
                // Add the slab's share, plane by plane of the grid (disjoint: in parallel).
                let u_slab = read_rgb(ctx, &self.u_out, (slab * m) as u64)?;
                let j_slab = if j.is_some() { Some(read_rgb(ctx, &self.j_out, slab as u64)?) } else { None };
                let add_u = |z: usize, up: &mut [Vec3]| {
                    slab_cells(grid.dims, &ff, w0, w1, z, |idx, k| {
                        let local = idx - z * plane;
                        for d in 0..m {
                            up[local * m + d] += u_slab[k * m + d];
                        }
                    })
                };
                match (j.as_deref_mut(), &j_slab) {
                    (Some(jv), Some(js)) => u_cur.par_chunks_mut(plane * m).zip(jv.par_chunks_mut(plane)).enumerate().for_each(|(z, (up, jp))| {
                        add_u(z, up);
                        slab_cells(grid.dims, &ff, w0, w1, z, |idx, k| jp[idx - z * plane] += js[k]);
                    }),
                    _ => u_cur.par_chunks_mut(plane * m).enumerate().for_each(|(z, up)| add_u(z, up)),
                }
                if progress.cancelled() {
                    return Err(Error::Cancelled);
                }
                stats.slabs += 1;
                cur = 1 - cur;
                w0 = w1;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
