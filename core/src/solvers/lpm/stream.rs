//! Slice streaming (Sec. 4.2) on the CPU: each face's sweep runs through slabs of `layers`
//! layers; the rays' radiance leaving a slab (the maps, one per direction) is carried into the
//! next, so the propagation's working memory is the maps plus one slab's temporary buffers,
//! p x map x (layers + 1) RGB values, whatever the volume's depth (the paper's
//! 4 nbSpect (S p n^2 + p n^2) terms). A slab is propagated and collected before the next
//! one starts, in the same order as one whole-volume slab, so streamed and in-memory solves
//! agree to the bit (tests.rs).
//!
//! Here the per-cell arrays (density, sigma_t, U of two orders, J) stay whole in memory and
//! only the propagation's buffers are bounded; `out_of_core: true` (out_of_core.rs) keeps
//! them in scratch files too, so that the whole solve is bounded by a slab.

use glam::Vec3;
use rayon::prelude::*;

use super::collect::{by_incoming, collect_layers, Targets};
use super::directions::{Directions, FACES};
use super::grid::LpmGrid;
use super::phase_table::PhaseTable;
use super::propagate::{propagate_layers, FaceFrame, Layers};
use crate::error::{Error, Result};
use crate::stages::Progress;

/// Bytes of the propagation's working buffers for a face whose map has `map_len` cells, `p`
/// directions reading `bins` storage bins and slabs of `layers` layers: the maps, the slab's
/// T, and the run of layers gathered for the sweep (`propagate::Layers`: sigma_t and the bins'
/// U, `run_layers` layers).
pub fn working_bytes(map_len: usize, p: usize, bins: usize, layers: usize) -> u64 {
    let gathered = (1 + bins as u64) * (map_len as u64) * run_layers(map_len, p, layers) as u64;
    ((p as u64) * (map_len as u64) * (layers as u64 + 1) + gathered) * std::mem::size_of::<Vec3>() as u64
}

/// Layers a sweep gathers and collects at a time in a slab of `layers` (`RUN_BYTES`): at
/// least one, at most the slab.
pub fn run_layers(map_len: usize, p: usize, layers: usize) -> usize {
    let layer_bytes = p * map_len * std::mem::size_of::<Vec3>();
    (RUN_BYTES / layer_bytes.max(1)).clamp(1, layers.max(1))
}

/// Slab thickness of each face: the whole depth when `memory_budget` is 0, else the most
/// layers whose working buffers fit it. Refused, with the size needed, when one layer does
/// not fit.
pub fn plan(dims: [usize; 3], dirs: &Directions, memory_budget: u64) -> Result<[usize; FACES]> {
    let (p, bins) = (dirs.per_face(), dirs.bins_per_face());
    let mut layers = [0usize; FACES];
    for (f, l) in layers.iter_mut().enumerate() {
        let ff = FaceFrame::from_dims(dims, f);
        if memory_budget == 0 {
            *l = ff.nw;
            continue;
        }
        let one = working_bytes(ff.map_len(), p, bins, 1);
        if one > memory_budget {
            return Err(Error::TooLarge(format!(
                "lpm: one slice (1 layer of {}x{} cells, {} directions) needs {} but memory_budget is {}; lower grid_resolution or directions, or raise memory_budget",
                ff.nu,
                ff.nv,
                dirs.per_face(),
                crate::budget::human(one),
                crate::budget::human(memory_budget)
            )));
        }
        *l = (1..=ff.nw).rev().find(|&k| working_bytes(ff.map_len(), p, bins, k) <= memory_budget).unwrap_or(1);
    }
    Ok(layers)
}

/// What the sweeps allocated: the largest working set (bytes, counted from the buffers'
/// capacities as they are allocated) and the number of slabs.
#[derive(Clone, Copy, Debug, Default)]
pub struct SweepStats {
    pub peak_working_bytes: u64,
    pub slabs: usize,
}

/// The propagation's working buffers (the maps, one slab's T and the gathered run of layers),
/// sized for the largest face and allocated once per solve: at 128^3 and 25 directions T is
/// 630 MB, whose first touch alone takes about a second, too long to repeat per face and order
/// or to do without looking at the cancel flag.
pub struct SweepBuffers {
    maps: Vec<Vec3>,
    t: Vec<Vec3>,
    gathered: Layers,
}

/// Bytes touched between two looks at the cancel flag while the buffers are first filled.
const FILL_CHUNK: usize = 1 << 20;

impl SweepBuffers {
    pub fn new(grid: &LpmGrid, dirs: &Directions, layers: &[usize; FACES], progress: &dyn Progress) -> Result<Self> {
        let p = dirs.per_face();
        let (mut maps_len, mut t_len, mut run_cells) = (0u64, 0u64, 0usize);
        for (f, &l) in layers.iter().enumerate() {
            let ff = FaceFrame::new(grid, f);
            let s = l.clamp(1, ff.nw.max(1));
            maps_len = maps_len.max(p as u64 * ff.map_len() as u64);
            t_len = t_len.max(p as u64 * s as u64 * ff.map_len() as u64);
            run_cells = run_cells.max(ff.map_len() * run_layers(ff.map_len(), p, s));
        }
        let maps = filled("lpm propagation maps", maps_len, progress)?;
        let t = filled("lpm slice buffer", t_len, progress)?;
        let bins = dirs.bins_per_face();
        crate::budget::check_elements::<Vec3>("lpm gathered layers", (run_cells * (1 + bins)) as u64)?;
        Ok(SweepBuffers { maps, t, gathered: Layers::with_capacity(run_cells, bins) })
    }

    fn bytes(&self) -> u64 {
        ((self.maps.capacity() + self.t.capacity()) * std::mem::size_of::<Vec3>()) as u64 + self.gathered.bytes()
    }
}

/// A zeroed buffer of `len` values, checked against the memory budget and filled a chunk at a
/// time so that a cancel lands within milliseconds.
pub fn filled(what: &str, len: u64, progress: &dyn Progress) -> Result<Vec<Vec3>> {
    let len = crate::budget::check_elements::<Vec3>(what, len)?;
    let mut v = Vec::with_capacity(len);
    while v.len() < len {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let n = (len - v.len()).min(FILL_CHUNK / std::mem::size_of::<Vec3>());
        v.resize(v.len() + n, Vec3::ZERO);
    }
    Ok(v)
}

/// What every sweep of a solve shares: the grid, the directions and their phase table, each
/// face's slab thickness, the viewer and the albedo.
#[derive(Clone, Copy)]
pub struct SweepSetup<'a> {
    pub grid: &'a LpmGrid,
    pub dirs: &'a Directions,
    pub table: &'a PhaseTable,
    pub layers: &'a [usize; FACES],
    pub camera: Vec3,
    pub albedo: Vec3,
}

/// Where the sweeps run: the CPU (`CpuSweeps`, below) or the GPU (volscatter-gpu's lpm
/// module). `start` is called once per solve, after the grid is built, and returns the
/// sweeper that keeps its working buffers (host or device memory) from order to order.
pub trait SweepBackend {
    fn start<'a>(&'a self, setup: SweepSetup<'a>, progress: &dyn Progress) -> Result<Box<dyn Sweeper + 'a>>;
}

/// One propagation order over all six faces: propagate from U of the previous order and the
/// boundary radiance (one value per direction), collect into U of this order (adding to
/// `u_cur`) and, when given, into J. A cancelled sweep returns `Error::Cancelled` and its U is
/// garbage.
pub trait Sweeper {
    fn sweep(&mut self, u_prev: &[Vec3], boundary: &[Vec3], u_cur: &mut [Vec3], j: Option<&mut [Vec3]>, stats: &mut SweepStats, progress: &dyn Progress) -> Result<()>;
}

/// The CPU backend: `sweep` below with buffers allocated once per solve.
pub struct CpuSweeps;

struct CpuSweeper<'a> {
    setup: SweepSetup<'a>,
    buffers: SweepBuffers,
}

impl SweepBackend for CpuSweeps {
    fn start<'a>(&'a self, setup: SweepSetup<'a>, progress: &dyn Progress) -> Result<Box<dyn Sweeper + 'a>> {
        let buffers = SweepBuffers::new(setup.grid, setup.dirs, setup.layers, progress)?;
        Ok(Box::new(CpuSweeper { setup, buffers }))
    }
}

impl Sweeper for CpuSweeper<'_> {
    fn sweep(&mut self, u_prev: &[Vec3], boundary: &[Vec3], u_cur: &mut [Vec3], j: Option<&mut [Vec3]>, stats: &mut SweepStats, progress: &dyn Progress) -> Result<()> {
        let s = &self.setup;
        sweep(s.grid, s.dirs, s.table, s.layers, u_prev, boundary, u_cur, j, s.camera, s.albedo, &mut self.buffers, stats, progress)
    }
}

/// One propagation order over all six faces on the CPU (see `Sweeper`).
/// One order over a 128^3 grid takes seconds, so propagate and collect look at the cancel
/// flag every layer.
#[allow(clippy::too_many_arguments)]
pub fn sweep(
    grid: &LpmGrid,
    dirs: &Directions,
    table: &PhaseTable,
    layers: &[usize; FACES],
    u_prev: &[Vec3],
    boundary: &[Vec3],
    u_cur: &mut [Vec3],
    mut j: Option<&mut [Vec3]>,
    camera: Vec3,
    albedo: Vec3,
    buffers: &mut SweepBuffers,
    stats: &mut SweepStats,
    progress: &dyn Progress,
) -> Result<()> {
    let p = dirs.per_face();
    stats.peak_working_bytes = stats.peak_working_bytes.max(buffers.bytes());
    for (f, &layers) in layers.iter().enumerate() {
        let ff = FaceFrame::new(grid, f);
        let s = layers.clamp(1, ff.nw.max(1));
        let maps = &mut buffers.maps[..p * ff.map_len()];
        let t = &mut buffers.t[..p * s * ff.map_len()];
        let first = f * p;
        let mut w0 = 0;
        while w0 < ff.nw {
            let w1 = (w0 + s).min(ff.nw);
            let slab = (w1 - w0) * ff.map_len();
            let targets = Targets { u_cur: &mut *u_cur, j: j.as_deref_mut(), camera, albedo };
            sweep_slab(grid, &ff, dirs, table, u_prev, &boundary[first..first + p], maps, &mut t[..p * slab], &mut buffers.gathered, (w0, w1), targets, progress);
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            stats.slabs += 1;
            w0 = w1;
        }
    }
    Ok(())
}

/// A face's slab is swept in runs of layers whose T (every direction's) is at most this many
/// bytes, each run propagated and then collected while its T is in cache; at least a layer.
const RUN_BYTES: usize = 256 << 10;

/// A run of fewer cells x directions than this runs on one thread: handing it to the thread
/// pool costs more than its work.
const PARALLEL_RUN: usize = 4096;

/// `f(k, chunk k of a, chunk k of b)` over `a` in chunks of `a_size` and `b` (when given) in
/// chunks of `b_size`, on the thread pool or on this thread.
pub(super) fn for_each_chunk<F>(parallel: bool, a: &mut [Vec3], a_size: usize, b: Option<&mut [Vec3]>, b_size: usize, f: F)
where
    F: Fn(usize, &mut [Vec3], Option<&mut [Vec3]>) + Send + Sync,
{
    match (b, parallel) {
        (Some(b), true) => a.par_chunks_mut(a_size).zip(b.par_chunks_mut(b_size)).enumerate().for_each(|(k, (x, y))| f(k, x, Some(y))),
        (Some(b), false) => a.chunks_mut(a_size).zip(b.chunks_mut(b_size)).enumerate().for_each(|(k, (x, y))| f(k, x, Some(y))),
        (None, true) => a.par_chunks_mut(a_size).enumerate().for_each(|(k, x)| f(k, x, None)),
        (None, false) => a.chunks_mut(a_size).enumerate().for_each(|(k, x)| f(k, x, None)),
    }
}

/// Propagates and collects layers `w0..w1` of face `ff`, a run of layers at a time (`RUN_BYTES`):
/// each run is gathered once for all the face's directions, which then run in parallel, and
/// collected while its T is in cache. Direction i's map is `maps`' i-th map-sized chunk, its T
/// the i-th slab-sized chunk of `t`, its boundary radiance `boundary[i]`; `layers` is the
/// caller's buffers for the gathered run (reset here). A run is at most a few ms; the caller
/// reports a cancel.
#[allow(clippy::too_many_arguments)]
pub(super) fn sweep_slab(grid: &LpmGrid, ff: &FaceFrame, dirs: &Directions, table: &PhaseTable, u_prev: &[Vec3], boundary: &[Vec3], maps: &mut [Vec3], t: &mut [Vec3], layers: &mut Layers, (w0, w1): (usize, usize), mut targets: Targets, progress: &dyn Progress) {
    let first = ff.face * dirs.per_face();
    let face_dirs = &dirs.dirs[first..first + dirs.per_face()];
    let map_len = ff.map_len();
    let slab = (w1 - w0) * map_len;
    let weights = by_incoming(dirs, table, ff.face);
    let run = run_layers(map_len, face_dirs.len(), w1 - w0);
    let parallel = map_len * face_dirs.len() * run >= PARALLEL_RUN;
    layers.reset(face_dirs, map_len, run);
    let slots: Vec<usize> = face_dirs.iter().map(|d| layers.slot(d)).collect();
    let mut wa = w0;
    while wa < w1 {
        if progress.cancelled() {
            return;
        }
        let ws = wa..(wa + run).min(w1);
        layers.gather(grid, ff, ws.clone(), table.m, u_prev, parallel);
        let gathered = &*layers;
        let (at, end) = ((ws.start - w0) * map_len, (ws.end - w0) * map_len);
        for_each_chunk(parallel, t, slab, Some(maps), map_len, |li, tc, map| {
            let map = map.expect("a map per direction");
            propagate_layers(ff, grid.h, &face_dirs[li], gathered, slots[li], boundary[li], map, ws.clone(), &mut tc[at..end]);
        });
        let run_targets = Targets { u_cur: &mut *targets.u_cur, j: targets.j.as_deref_mut(), camera: targets.camera, albedo: targets.albedo };
        collect_layers(grid, dirs, table, &weights, ff, &t[at..], slab, ws.clone(), run_targets, parallel);
        wa = ws.end;
    }
}
