//! The out-of-core solve (`out_of_core: true`, Sec. 4.2 taken to the whole solve): every
//! per-cell array lives in a scratch file (slab_store.rs) and a sweep reads and writes one
//! slab at a time, so the solve's memory is bounded by a slab whatever the grid's size.
//!
//! Design:
//! - The arrays: sigma_t and the density guide (one value a cell), U of two orders (m a
//!   cell), J (one a cell), each a `SlabStore` in the scratch directory (the `Lpm`'s
//!   `scratch_dir`, else the system temp dir: `TMPDIR` on Unix). Each file is removed when
//!   the solve returns, on success, error or cancel (the stores' `Drop`).
//! - Building: the grid's cells are sampled z-slab by z-slab (`LpmGrid::block`, the same
//!   values as a whole grid) and written out; emission goes into U of the first propagation
//!   in the same pass.
//! - A sweep: for each face and each slab of `layers` layers along the face's axis, the slab's
//!   box (whole in the other two axes) of sigma_t, U of the previous order, U of this order
//!   and J is read, propagated and collected by the in-memory code (propagate.rs, collect.rs:
//!   the box is an `LpmGrid` with an `offset`), and written back. The maps carry the rays to
//!   the next slab as in memory. Faces, slabs, cells and their sums run in the in-memory
//!   order, so J and U are equal to the bit (tests.rs).
//! - Memory: `plan` picks each face's slab thickness so that the maps, the slab's T and the
//!   four boxes fit `memory_budget`: map x (p (layers + 1) + layers (2m + 2)) RGB values.
//!   The output (S at `output_resolution`, the compositor's exact single scattering plus the
//!   upsampled J) is a fixed size, independent of the grid; it is upsampled a window of J's
//!   planes at a time (pop's `upsample_plane`, the same values as the whole), and with
//!   `Lpm::with_s_vdb` it goes to the VDB 8 planes at a time once its points are made for
//!   trilinear rendering (lattice_product.rs, which needs each plane's neighbours;
//!   vdb/stream_writer.rs).
//! - The medium: the cells are sampled from the scene's medium and pop's density mip, both in
//!   memory. For a VDB larger than memory the scene reads it box-filtered to a working
//!   resolution (`medium.max_resolution`, vdb/filter.rs: the file through a 64 KiB window,
//!   two passes, never whole), so that what is held is the coarse medium, not the voxels;
//!   the mip, the guard's checks and the compositor's exact single scattering run on it
//!   unchanged. Why not a read per slab here: the cells need the mip's footprint average
//!   (a slab's reads would need the neighbours' leaves too), the compositor's single
//!   scattering marches through the whole medium, and the VDB's leaves are stored in x-major
//!   topology order, so a z-slab's read steps over the whole file each time; one filtered
//!   pass reads it once. Measured (out_of_core_tests.rs): a medium filtered to twice the
//!   grid's resolution moves the plume's image by 0.017 rel. RMSE, to the grid's own 0.041.
//! - Not streamed: what needs random access to the whole grid: the exact first order of
//!   distant lights (`first_order: exact`) and local lights, refused with a message
//!   (`boundary` streams: the sun enters as boundary radiance).

use std::path::Path;

use glam::Vec3;

use super::collect::Targets;
use super::delta_m::DeltaM;
use super::directions::{Directions, FACES};
use super::grid::LpmGrid;
use super::phase_table::PhaseTable;
use super::propagate::{FaceFrame, Layers};
use super::slab_store::SlabStore;
use super::stream::{sweep_slab, SweepStats};
use super::{lights, FirstOrder, Lpm, LpmReport, Overrides};
use crate::error::{Error, Result};
use crate::scene::{Light, Scene};
use crate::stages::upsample::footprint;
use crate::stages::mip::MediumMip;
use crate::stages::upsample::{upsample_plane, CoarseWindow, Upsampling};
use crate::solvers::SolveOutput;
use crate::stages::{Progress, ScatteringGrid, Timings};
use crate::vdb::RgbVdbStream;

const VEC3: u64 = std::mem::size_of::<Vec3>() as u64;

/// Bytes one slab of `layers` layers needs out of core: the maps, T and the gathered run
/// (`stream::working_bytes`, `bins` storage bins a face) plus the slab's boxes of sigma_t, U
/// in, U out (m values a cell each) and J.
pub fn slab_bytes(map_len: usize, p: usize, bins: usize, m: usize, layers: usize) -> u64 {
    super::stream::working_bytes(map_len, p, bins, layers) + map_len as u64 * layers as u64 * (2 * m as u64 + 2) * VEC3
}

/// Slab thickness of each face out of core: the most layers whose `slab_bytes` fit
/// `memory_budget` (the whole depth when it is 0); refused, with the size needed, when one
/// layer does not fit.
pub fn plan(dims: [usize; 3], dirs: &Directions, m: usize, memory_budget: u64) -> Result<[usize; FACES]> {
    let (p, bins) = (dirs.per_face(), dirs.bins_per_face());
    let mut layers = [0usize; FACES];
    for (f, l) in layers.iter_mut().enumerate() {
        let ff = FaceFrame::from_dims(dims, f);
        if memory_budget == 0 {
            *l = ff.nw;
            continue;
        }
        let one = slab_bytes(ff.map_len(), p, bins, m, 1);
        if one > memory_budget {
            return Err(Error::TooLarge(format!(
                "lpm out of core: one slice (1 layer of {}x{} cells, {p} directions, {m} storage bins) needs {} but memory_budget is {}; lower grid_resolution or directions, or raise memory_budget",
                ff.nu,
                ff.nv,
                crate::budget::human(one),
                crate::budget::human(memory_budget)
            )));
        }
        *l = (1..=ff.nw).rev().find(|&k| slab_bytes(ff.map_len(), p, bins, m, k) <= memory_budget).unwrap_or(1);
    }
    Ok(layers)
}

/// Lights whose first order needs the whole grid at once: refused out of core.
fn refuse_unstreamed_lights(scene: &Scene, mode: FirstOrder) -> Result<()> {
    for light in &scene.lights {
        let why = match light {
            Light::Dome(_) => None,
            Light::Distant { .. } if mode == FirstOrder::Boundary => None,
            Light::Distant { .. } => Some("a distant light with first_order exact (set first_order to boundary: the sun then enters as boundary radiance, which streams)"),
            _ => Some("a local light (point, spot, sphere or area: its exact first order marches to every cell through the whole grid)"),
        };
        if let Some(why) = why {
            return Err(Error::scene("solver.out_of_core", format!("lpm out of core does not stream {why}; solve in memory (out_of_core false) or leave the light out")));
        }
    }
    Ok(())
}

/// The per-cell stores of one solve (removed on drop).
struct Stores {
    sigma_t: SlabStore,
    density: SlabStore,
    u_prev: SlabStore,
    u_cur: SlabStore,
    j: SlabStore,
}

impl Stores {
    fn create(dir: &Path, dims: [usize; 3], m: usize) -> Result<Self> {
        Ok(Stores {
            sigma_t: SlabStore::create(dir, "sigma_t", dims, 1)?,
            density: SlabStore::create(dir, "density", dims, 1)?,
            u_prev: SlabStore::create(dir, "u_a", dims, m)?,
            u_cur: SlabStore::create(dir, "u_b", dims, m)?,
            j: SlabStore::create(dir, "j", dims, 1)?,
        })
    }

    fn disk_bytes(&self) -> u64 {
        [&self.sigma_t, &self.density, &self.u_prev, &self.u_cur, &self.j].iter().map(|s| s.bytes()).sum()
    }
}

/// Box of the slab `w0..w1` of face `ff` in grid coordinates.
fn slab_box(dims: [usize; 3], ff: &FaceFrame, w0: usize, w1: usize) -> ([usize; 3], [usize; 3]) {
    let (a0, a1) = if ff.forward { (w0, w1) } else { (ff.nw - w1, ff.nw - w0) };
    let (mut lo, mut hi) = ([0; 3], dims);
    lo[ff.axes.2] = a0;
    hi[ff.axes.2] = a1;
    (lo, hi)
}

/// What every out-of-core sweep shares.
struct Sweeps<'a> {
    geometry: ([usize; 3], Vec3, f32),
    dirs: &'a Directions,
    table: &'a PhaseTable,
    layers: [usize; FACES],
    camera: Vec3,
    albedo: Vec3,
}

impl Sweeps<'_> {
    /// One order (as `stream::sweep`) from `stores.u_prev` into `stores.u_cur` (overwritten:
    /// the first face starts each box from zero) and, when `with_j`, into `stores.j`.
    /// Returns the largest U of the order.
    fn sweep(&self, stores: &Stores, boundary: &[Vec3], with_j: bool, stats: &mut SweepStats, progress: &dyn Progress) -> Result<f32> {
        let (dims, lo_world, h) = self.geometry;
        let p = self.dirs.per_face();
        let m = self.table.m;
        let (mut maps, mut t, mut u_prev, mut u_cur, mut j) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut gathered = Layers::with_capacity(0, 0);
        let mut sub = LpmGrid { dims, lo: lo_world, h, offset: [0; 3], density: Vec::new(), sigma_t: Vec::new() };
        let mut largest = 0.0f32;
        for f in 0..FACES {
            let ff = FaceFrame::from_dims(dims, f);
            let s = self.layers[f].clamp(1, ff.nw.max(1));
            maps.resize(p * ff.map_len(), Vec3::ZERO);
            let mut w0 = 0;
            while w0 < ff.nw {
                let w1 = (w0 + s).min(ff.nw);
                let (lo, hi) = slab_box(dims, &ff, w0, w1);
                sub.offset = lo;
                sub.dims = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
                stores.sigma_t.read_box(lo, hi, &mut sub.sigma_t)?;
                stores.u_prev.read_box(lo, hi, &mut u_prev)?;
                if f == 0 {
                    u_cur.clear();
                    u_cur.resize(sub.len() * m, Vec3::ZERO);
                } else {
                    stores.u_cur.read_box(lo, hi, &mut u_cur)?;
                }
                if with_j {
                    stores.j.read_box(lo, hi, &mut j)?;
                }
                let slab = (w1 - w0) * ff.map_len();
                t.resize(p * slab, Vec3::ZERO);
                let targets = Targets { u_cur: &mut u_cur, j: with_j.then_some(&mut j[..]), camera: self.camera, albedo: self.albedo };
                sweep_slab(&sub, &ff, self.dirs, self.table, &u_prev, &boundary[f * p..(f + 1) * p], &mut maps, &mut t, &mut gathered, (w0, w1), targets, progress);
                if progress.cancelled() {
                    return Err(Error::Cancelled);
                }
                stores.u_cur.write_box(lo, hi, &u_cur)?;
                if with_j {
                    stores.j.write_box(lo, hi, &j)?;
                }
                if f == FACES - 1 {
                    // The last face writes every cell once: U of this order is final there.
                    largest = u_cur.iter().fold(largest, |a, x| a.max(x.abs().max_element()));
                }
                let held = maps.capacity() + t.capacity() + sub.sigma_t.capacity() + u_prev.capacity() + u_cur.capacity() + j.capacity();
                stats.peak_working_bytes = stats.peak_working_bytes.max(held as u64 * VEC3 + gathered.bytes());
                stats.slabs += 1;
                w0 = w1;
            }
        }
        Ok(largest)
    }
}

/// sigma_t' = sigma_t (1 - albedo f) in the store, a z-plane at a time (as
/// `DeltaM::scale_extinction` does to a whole grid in memory).
fn scale_extinction(sigma_t: &SlabStore, dims: [usize; 3], delta: &DeltaM, progress: &dyn Progress) -> Result<()> {
    let mut v = Vec::new();
    for z in 0..dims[2] {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        sigma_t.read_box([0, 0, z], [dims[0], dims[1], z + 1], &mut v)?;
        delta.scale_extinction(&mut v);
        sigma_t.write_box([0, 0, z], [dims[0], dims[1], z + 1], &v)?;
    }
    Ok(())
}

/// j = max(j - j_true, 0) a z-plane at a time: the light the forward peak scattered on (the
/// true medium's share is the compositor's exact single scattering). Non-negative up to
/// rounding, as in memory.
fn subtract_clamped(j: &SlabStore, j_true: &SlabStore, dims: [usize; 3], progress: &dyn Progress) -> Result<()> {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for z in 0..dims[2] {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        j.read_box([0, 0, z], [dims[0], dims[1], z + 1], &mut a)?;
        j_true.read_box([0, 0, z], [dims[0], dims[1], z + 1], &mut b)?;
        for (x, y) in a.iter_mut().zip(&b) {
            *x = (*x - *y).max(Vec3::ZERO);
        }
        j.write_box([0, 0, z], [dims[0], dims[1], z + 1], &a)?;
    }
    Ok(())
}

/// Builds the stores z-slab by z-slab: sigma_t and density, and the emission into U of the
/// first propagation (every storage bin, as `lights::emission_source`).
fn build(scene: &Scene, mip: &MediumMip, geometry: ([usize; 3], Vec3, f32), thickness: usize, m: usize, stores: &Stores, progress: &dyn Progress) -> Result<()> {
    let medium = &scene.medium;
    let dims = geometry.0;
    let mut z0 = 0;
    let mut v = Vec::new();
    while z0 < dims[2] {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let z1 = (z0 + thickness).min(dims[2]);
        let (lo, hi) = ([0, 0, z0], [dims[0], dims[1], z1]);
        let block = LpmGrid::block(medium, mip, geometry, lo, [dims[0], dims[1], z1 - z0]);
        stores.sigma_t.write_box(lo, hi, &block.sigma_t)?;
        v.clear();
        v.extend(block.density.iter().map(|&d| Vec3::new(d, 0.0, 0.0)));
        stores.density.write_box(lo, hi, &v)?;
        if let Some(em) = &medium.emission {
            v.clear();
            for z in z0..z1 {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let e = em.at(block.centre([x, y, z]));
                        v.extend(std::iter::repeat_n(Vec3::ZERO + e, m));
                    }
                }
            }
            stores.u_prev.write_box(lo, hi, &v)?;
        }
        z0 = z1;
    }
    Ok(())
}

/// The solve with every per-cell array in `scratch` (see the module docs).
pub(super) fn solve(lpm: &Lpm, scene: &Scene, progress: &dyn Progress, ov: Overrides, scratch: &Path) -> Result<(SolveOutput, LpmReport)> {
    let s = lpm.settings();
    let medium = &scene.medium;
    let mut timings = Timings::default();
    let mut report = LpmReport::default();
    refuse_unstreamed_lights(scene, s.first_order)?;
    let (out_probe, single) = super::output_start(s, scene, progress, ov, &mut timings)?;
    if !super::scatters(scene) {
        return Ok((SolveOutput::new(crate::lattice_product::finished(medium, single), timings), report));
    }
    let geometry = LpmGrid::geometry(medium, s.grid_resolution);
    let (dims, _, h) = geometry;
    let cell_fp = h / medium.voxel_size_world().max_element();
    let mip = timings.time("lpm mip", || MediumMip::new(medium, cell_fp.min(footprint(medium, &out_probe))));
    report.grid_dims = dims;
    let dirs = Directions::new(s.lattice_side() as usize, s.storage_per_face as usize);
    let table = timings.time("lpm phase table", || PhaseTable::true_phase(&dirs, medium.g))?;
    let m = table.m;
    report.layers = match ov.layers {
        Some(l) => [l.max(1); FACES],
        None => plan(dims, &dirs, m, s.memory_budget)?,
    };
    let mut stores = Stores::create(scratch, dims, m)?;
    report.cell_bytes = stores.disk_bytes();
    let thickness = report.layers.iter().copied().min().unwrap_or(1).max(1);
    timings.time("lpm grid (out of core)", || build(scene, &mip, geometry, thickness, m, &stores, progress))?;
    // The delta-M split as in memory (mod.rs): the first propagation runs through the true
    // medium and then through sigma_t' with the residual lobe, J keeping their difference;
    // the later orders run through sigma_t' alone.
    let delta = DeltaM::for_bins(s.delta_m, s.peak_split, medium.g, medium.albedo, &dirs)?;
    let scaled_table = if delta.active() { Some(timings.time("lpm phase table", || delta.table(&dirs, &table))?) } else { None };
    let truth = Sweeps { geometry, dirs: &dirs, table: &table, layers: report.layers, camera: scene.camera.position, albedo: medium.albedo };
    let sweeps = Sweeps { table: scaled_table.as_ref().unwrap_or(&table), albedo: delta.albedo, ..truth };
    let boundary = lights::boundary(scene, &dirs, s.first_order);
    let zero_boundary = vec![Vec3::ZERO; dirs.len()];
    let first_max = if lights::first_propagation_needed(&boundary, scene) {
        let max = timings.time("lpm first order", || -> Result<f32> {
            if !delta.active() {
                return truth.sweep(&stores, &boundary, false, &mut report.sweep, progress);
            }
            // J of the true medium's first propagation, in a scratch store of its own (the
            // stores' J swapped out for the pass), then subtracted from the scaled one's.
            let mut j_true = SlabStore::create(scratch, "j_true", dims, 1)?;
            std::mem::swap(&mut stores.j, &mut j_true);
            let swept = truth.sweep(&stores, &boundary, true, &mut report.sweep, progress);
            std::mem::swap(&mut stores.j, &mut j_true);
            swept?;
            scale_extinction(&stores.sigma_t, dims, &delta, progress)?;
            let max = sweeps.sweep(&stores, &boundary, true, &mut report.sweep, progress)?;
            subtract_clamped(&stores.j, &j_true, dims, progress)?;
            Ok(max)
        })?;
        std::mem::swap(&mut stores.u_prev, &mut stores.u_cur);
        max
    } else {
        0.0
    };
    report.max_u.push(first_max);
    if !progress.update("lpm propagate", 0.1) {
        return Err(Error::Cancelled);
    }
    timings.time("lpm propagate", || -> Result<()> {
        while first_max > 0.0 && report.orders < s.max_orders as usize && *report.max_u.last().unwrap_or(&0.0) > s.epsilon * first_max {
            let max = sweeps.sweep(&stores, &zero_boundary, true, &mut report.sweep, progress)?;
            std::mem::swap(&mut stores.u_prev, &mut stores.u_cur);
            report.max_u.push(max);
            report.orders += 1;
            let done = (report.orders as f32 / s.max_orders as f32).max((s.epsilon * first_max / max.max(1e-30)).min(1.0));
            if !progress.update("lpm propagate", 0.1 + 0.8 * done) {
                return Err(Error::Cancelled);
            }
        }
        Ok(())
    })?;
    let whole = |store: &SlabStore| -> Result<Vec<Vec3>> {
        let mut v = Vec::new();
        store.read_box([0; 3], dims, &mut v)?;
        Ok(v)
    };
    if ov.j_only {
        // For tests: J whole, as the in-memory solve reports it.
        let frame = LpmGrid { dims, lo: geometry.1, h, offset: [0; 3], density: Vec::new(), sigma_t: Vec::new() };
        report.j = Some(frame.as_scattering_grid(whole(&stores.j)?));
        return Ok((SolveOutput::new(crate::lattice_product::finished(medium, single), timings), report));
    }
    let pop_like = s.upsampling();
    // Created before the solve: a path that cannot be written fails now, not after it.
    let vdb = match lpm.s_vdb.as_deref() {
        Some(p) => Some(RgbVdbStream::create(p, "scattering", out_probe.dims, out_probe.index_to_world, &Default::default())?),
        None => None,
    };
    let scattering = timings.time("lpm upsample (out of core)", || upsample_streamed(scene, &mip, &stores, geometry, &pop_like, &single, progress))?;
    // The in-memory solve's points (lattice_product.rs), then to the file as they are returned.
    let scattering = crate::lattice_product::finished(medium, scattering);
    if let Some(mut v) = vdb {
        timings.time("lpm S to VDB", || {
            let plane = (scattering.dims[0] * scattering.dims[1]) as usize;
            for chunk in scattering.data.chunks(plane * OUTPUT_PLANES) {
                v.push_planes(chunk)?;
            }
            v.finish()
        })?;
    }
    progress.update("lpm upsample", 1.0);
    Ok((SolveOutput::new(scattering, timings), report))
}

/// Output planes this many at a time (each reads the window of J's planes it needs).
const OUTPUT_PLANES: usize = 8;

/// pop's upsampling of J (in `stores.j`) to the output grid, `OUTPUT_PLANES` output planes at a
/// time, each reading only the coarse planes its points and the filter reach.
#[allow(clippy::too_many_arguments)]
fn upsample_streamed(
    scene: &Scene,
    mip: &MediumMip,
    stores: &Stores,
    geometry: ([usize; 3], Vec3, f32),
    settings: &Upsampling,
    single: &ScatteringGrid,
    progress: &dyn Progress,
) -> Result<ScatteringGrid> {
    use rayon::prelude::*;
    let medium = &scene.medium;
    let (dims, lo_world, h) = geometry;
    let mut out = ScatteringGrid::over_medium(medium, settings.output_resolution)?;
    let frame = LpmGrid { dims, lo: lo_world, h, offset: [0; 3], density: Vec::new(), sigma_t: Vec::new() }.frame();
    let to_coarse = frame.inverse();
    // The range sigma's scale: the whole grid's largest density, a pass over its store.
    let mut max_density = 0.0f32;
    let mut v = Vec::new();
    for z in 0..dims[2] {
        stores.density.read_box([0, 0, z], [dims[0], dims[1], z + 1], &mut v)?;
        max_density = v.iter().fold(max_density, |a, d| a.max(d.x));
    }
    let max_density = max_density.max(1e-12);
    let radius = (2.0 * settings.spatial_sigma).ceil().max(1.0) as i32;
    let [nx, ny, nz] = out.dims;
    let plane = (nx * ny) as usize;
    let (odims, oframe, fp) = (out.dims, out.index_to_world, footprint(medium, &out));
    let (mut j, mut dens) = (Vec::new(), Vec::new());
    for (c, chunk) in out.data.chunks_mut(plane * OUTPUT_PLANES).enumerate() {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let k0 = c * OUTPUT_PLANES;
        let k1 = (k0 + OUTPUT_PLANES).min(nz as usize);
        // The coarse z of the chunk's corners bound its points' (the maps are affine).
        let (mut zmin, mut zmax) = (f32::INFINITY, f32::NEG_INFINITY);
        for k in [k0, k1 - 1] {
            for (i, jj) in [(0, 0), (nx - 1, 0), (0, ny - 1), (nx - 1, ny - 1)] {
                let q = to_coarse.transform_point3(oframe.transform_point3(Vec3::new(i as f32, jj as f32, k as f32)));
                zmin = zmin.min(q.z);
                zmax = zmax.max(q.z);
            }
        }
        let z0 = (zmin.floor() as i64 - radius as i64).clamp(0, dims[2] as i64) as usize;
        let z1 = (zmax.floor() as i64 + radius as i64 + 2).clamp(z0 as i64, dims[2] as i64) as usize;
        stores.j.read_box([0, 0, z0], [dims[0], dims[1], z1], &mut j)?;
        stores.density.read_box([0, 0, z0], [dims[0], dims[1], z1], &mut v)?;
        dens.clear();
        dens.extend(v.iter().map(|d| d.x));
        let window_grid = ScatteringGrid { dims: [dims[0] as u32, dims[1] as u32, (z1 - z0) as u32], index_to_world: frame, data: std::mem::take(&mut j) };
        let win = CoarseWindow { j: &window_grid, density: &dens, z0, to_coarse, max_density };
        chunk.par_chunks_mut(plane).enumerate().for_each(|(dk, slab)| upsample_plane(medium, mip, &win, settings, (odims, oframe, fp), k0 + dk, slab));
        j = window_grid.data;
        // S = the upsampled multiple scattering + the exact single scattering, as in memory.
        for (a, b) in chunk.iter_mut().zip(&single.data[k0 * plane..]) {
            *a += *b;
        }
    }
    Ok(out)
}
