//! `lpm`: light propagation maps (paper 05, after Fattal 2009), CPU, first landing.
//!
//! A discrete-ordinates solver: the medium on a grid of cubic cells (grid.rs), 6 x n
//! propagation directions, n per cube face, and m storage directions (directions.rs), the
//! phase table F of Eq. 5 between them (phase_table.rs). Each order propagates every face's
//! map of rays layer by layer through the grid (propagate.rs, Eq. 3), then collects what the
//! rays left in each cell into U of the next order and, towards the camera, into J
//! (collect.rs, Eq. 4); the split needs no atomics (Sec. 4.1). Orders run until the largest U
//! falls below `epsilon` times the first order's (Fattal's criterion); a solve predicted to
//! take hundreds runs its late ones over fewer directions (coarse.rs) and ends on their
//! geometric tail (tail.rs). The sweeps run in slabs
//! whose working memory fits `memory_budget` (stream.rs, Sec. 4.2).
//!
//! S = (the compositor's exact single scattering) + sigma_s x J upsampled by pop's
//! density-guided filter, with trilinear weights in place of its Gaussian (`spatial_sigma` 0:
//! J is interpolated, not smoothed). The first propagation (dome, emission, and the sun in
//! `boundary` mode) and the exact first order of the other lights (lights.rs) make U of the
//! first order; J gathers orders two and up.
//!
//! Departures from the paper, each where it is made: T is the exact segment mean
//! (propagate.rs); J from the fine bins (collect.rs); exact first order for distant and local
//! lights (lights.rs); the phase table normalised (phase_table.rs); the delta-M split of the
//! phase function's forward peak (delta_m.rs, setting `delta_m`, on): the propagated light
//! runs through sigma_t (1 - albedo g^2) and scatters into U by the residual lobe g / (1 + g);
//! S's single scattering and the phase towards the viewer stay true.
//!
//! The sweeps run through a `stream::SweepBackend`: the CPU's here, the GPU's kernels in
//! volscatter-gpu (its lpm module). With `out_of_core` the per-cell arrays live in scratch
//! files too, read and written a slab at a time (out_of_core.rs): the whole solve is bounded by
//! `memory_budget`, not only the sweeps.

pub mod coarse;
mod collect;
pub mod cost;
pub mod delta_m;
pub mod directions;
pub mod estimate;
pub mod grid;
pub mod lights;
pub mod out_of_core;
pub mod phase_table;
pub mod propagate;
pub mod settings;
pub mod slab_store;
pub mod stream;
pub mod tail;
#[cfg(test)]
mod out_of_core_tests;
#[cfg(test)]
mod tests;

pub use settings::{FirstOrder, LpmSettings};

use glam::Vec3;

use crate::stages::upsample::{footprint, Merged};
use crate::stages::mip::MediumMip;
use crate::stages::upsample::upsample;
use super::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Counters, Progress, Timings};
use crate::stages::single_scattering::single_scattering_grid_dome_spaced;
use crate::error::{Error, Result};
use crate::scene::Scene;
use directions::{Directions, FACES};
use grid::LpmGrid;
use phase_table::PhaseTable;

#[derive(Clone)]
pub struct Lpm {
    settings: LpmSettings,
    /// Where `out_of_core` puts its scratch files (None: the system temp dir).
    scratch_dir: Option<std::path::PathBuf>,
    /// Where S also goes as a VDB (`scattering_r/_g/_b`): out of core written plane by plane
    /// as it is upsampled, in memory written whole.
    s_vdb: Option<std::path::PathBuf>,
    /// Test and benchmark knobs (`with_overrides`).
    overrides: Overrides,
}

/// What a solve did, for tests and benchmarks.
#[derive(Clone, Debug, Default)]
pub struct LpmReport {
    pub grid_dims: [usize; 3],
    /// Largest U (max over cells, bins and channels) of each order from the first.
    pub max_u: Vec<f32>,
    /// Propagations after the first order's (each gives J one more order).
    pub orders: usize,
    /// Of those, the late ones run over fewer directions (coarse.rs).
    pub coarse_orders: usize,
    /// The factor of the last sweep, which added the geometric tail of the orders not run
    /// (tail.rs); None when the orders ran to `epsilon` or `max_orders`.
    pub tail_factor: Option<Vec3>,
    /// What the user should hear (the cost guard's prediction), passed on as the solve's notes.
    pub notes: Vec<String>,
    pub layers: [usize; FACES],
    pub sweep: stream::SweepStats,
    /// Bytes of the per-cell arrays (density, sigma_t, two U, J).
    pub cell_bytes: u64,
    /// J (in-scattered radiance per unit sigma_s, orders two and up) on the cell centres.
    pub j: Option<crate::stages::ScatteringGrid>,
    /// J of each order (when asked for: `keep_orders`).
    pub j_per_order: Vec<Vec<Vec3>>,
}

/// Overrides for tests and benchmarks.
#[derive(Clone, Copy, Debug, Default)]
pub struct Overrides {
    /// Slab thickness for every face instead of the budget's plan.
    pub layers: Option<usize>,
    /// Keep J of every order in the report.
    pub keep_orders: bool,
    /// Skip the upsampled output (the report's J is enough).
    pub j_only: bool,
    /// Run every order over the solve's directions (coarse.rs's late orders off).
    pub fine_orders_only: bool,
}

fn max_abs(v: &[Vec3]) -> f32 {
    v.iter().fold(0.0f32, |a, x| a.max(x.abs().max_element()))
}

impl Lpm {
    pub fn new(settings: LpmSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Lpm { settings, scratch_dir: None, s_vdb: None, overrides: Overrides::default() })
    }

    /// The directory of `out_of_core`'s scratch files (default: `std::env::temp_dir()`).
    pub fn with_scratch_dir(mut self, dir: impl Into<std::path::PathBuf>) -> Self {
        self.scratch_dir = Some(dir.into());
        self
    }

    /// Also write S to the VDB file `path` (see the field).
    pub fn with_s_vdb(mut self, path: impl Into<std::path::PathBuf>) -> Self {
        self.s_vdb = Some(path.into());
        self
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Lpm::new(parse_settings(map)?)
    }

    pub fn settings(&self) -> &LpmSettings {
        &self.settings
    }

    /// This solver with the test and benchmark knobs `ov`.
    pub fn with_overrides(&self, ov: Overrides) -> Self {
        Lpm { overrides: ov, ..self.clone() }
    }

    fn run(&self, scene: &Scene, ctx: &mut SolveCtx, backend: &dyn stream::SweepBackend, counters: &mut Counters) -> Result<(SolveOutput, LpmReport)> {
        let ov = self.overrides;
        let s = &self.settings;
        let progress = ctx.progress();
        if s.out_of_core {
            // The CPU's: the GPU's sweeps keep their arrays on the device.
            let dir = self.scratch_dir.clone().unwrap_or_else(std::env::temp_dir);
            return out_of_core::solve(self, scene, progress, ov, &dir);
        }
        let medium = &scene.medium;
        let mut timings = Timings::default();
        let mut report = LpmReport::default();
        let out_probe = crate::stages::ScatteringGrid::over_medium(&scene.medium, s.output_size())?;
        // In a session, the parts of the single scattering whose lights did not change are kept.
        let single = if ov.j_only {
            out_probe.clone()
        } else {
            timings.time("lpm single scattering", || ctx.single_scattering(scene, s.output_size(), s.dome_directions_for(medium.g), COARSEST_DOME, counters))?
        };
        if !scatters(scene) {
            return Ok((SolveOutput::new(crate::lattice_product::finished(medium, single), timings), report));
        }
        // The mip serves both the cells' mean density and the upsampling.
        let (lo, hi) = medium.world_bounds();
        let h = (hi - lo).max_element() / s.grid_resolution as f32;
        let cell_fp = h / medium.voxel_size_world().max_element();
        let mip = timings.time("lpm mip", || MediumMip::new(medium, cell_fp.min(footprint(medium, &out_probe))));
        let mut grid = timings.time("lpm grid", || LpmGrid::new(medium, s.grid_resolution, &mip))?;
        report.grid_dims = grid.dims;
        let dirs = Directions::new(s.lattice_side() as usize, s.storage_per_face as usize);
        // The cost guard (cost.rs): a solve of hundreds of orders says so before they run.
        let (orders, tau) = cost::predicted_orders(&grid, medium.albedo, medium.g, s.epsilon, s.max_orders);
        // Hundreds of orders run mostly over fewer directions (coarse.rs), at a few times a usual cost.
        let coarse_late_orders = coarse::engaged(orders, &dirs) && !ov.keep_orders && !ov.fine_orders_only;
        let slow = if coarse_late_orders { None } else { cost::note(orders, tau, medium.albedo, grid.len(), dirs.len()) };
        if let Some(n) = &slow {
            if !progress.update(&format!("lpm: about {orders} orders, minutes (see the note)"), 0.0) {
                return Err(Error::Cancelled);
            }
            report.notes.push(n.clone());
        }
        let table = timings.time("lpm phase table", || PhaseTable::true_phase(&dirs, medium.g))?;
        let delta = timings.time("lpm phase table", || delta_m::DeltaM::for_bins(s.delta_m, s.peak_split, medium.g, medium.albedo, &dirs))?;
        let scaled_table = if delta.active() { Some(timings.time("lpm phase table", || delta.table(&dirs, &table))?) } else { None };
        let m = table.m;
        let cells = grid.len() as u64;
        let mut u_prev = stream::filled("lpm U (cells x storage directions)", cells * m as u64, progress)?;
        let mut u_cur = stream::filled("lpm U (cells x storage directions)", cells * m as u64, progress)?;
        let mut j = stream::filled("lpm J", cells, progress)?;
        report.cell_bytes = estimate::cell_bytes(cells, m);
        report.layers = match ov.layers {
            Some(l) => [l.max(1); FACES],
            None => stream::plan(grid.dims, &dirs, s.memory_budget)?,
        };
        let layers = report.layers;
        let camera = scene.camera.position;
        let zero_boundary = vec![Vec3::ZERO; dirs.len()];

        // First order, split by delta-M (delta_m.rs): the first propagation (dome, emission,
        // sun as boundary) and the exact first scattering of the other lights. Under the split
        // the unscattered light goes through sigma_t' (on the sweeper of the later orders,
        // below), and J gets what it scatters towards the viewer less what the same sweep
        // through the true medium gives (the compositor's single scattering): the light the
        // peak scattered on.
        let boundary = lights::boundary(scene, &dirs, s.first_order);
        let first_propagation = lights::first_propagation_needed(&boundary, scene);
        let mut kept = None;
        let mut j_true = None;
        timings.time("lpm first order", || -> Result<()> {
            if first_propagation {
                let setup = stream::SweepSetup { grid: &grid, dirs: &dirs, table: &table, layers: &layers, camera, albedo: medium.albedo };
                let mut sweeper = backend.start(setup, progress)?;
                lights::emission_source(scene, &grid, m, &mut u_prev);
                if delta.active() {
                    let mut jt = stream::filled("lpm J", cells, progress)?;
                    sweeper.sweep(&u_prev, &boundary, &mut u_cur, Some(&mut jt), &mut report.sweep, progress)?;
                    u_cur.iter_mut().for_each(|v| *v = Vec3::ZERO);
                    j_true = Some(jt);
                } else {
                    sweeper.sweep(&u_prev, &boundary, &mut u_cur, None, &mut report.sweep, progress)?;
                    kept = Some(sweeper);
                }
            }
            lights::add_first_order(scene, &grid, &dirs, scaled_table.as_ref().unwrap_or(&table), &delta, s.first_order, &mut u_cur, &mut j, progress);
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            Ok(())
        })?;
        // The later orders' sweeper: through sigma_t' with the residual lobe under delta-M
        // (the true medium's sweeper given back first), else the first propagation's.
        // (Not `if let`/`match` on `kept`: the borrow checker would keep its borrow of the grid
        // alive in the branch that scales the grid; dropping it there ends the borrow.)
        let reuse = kept.is_some();
        let mut sweeper = if reuse {
            kept.expect("checked above")
        } else {
            drop(kept);
            delta.scale_extinction(&mut grid.sigma_t);
            let table = scaled_table.as_ref().unwrap_or(&table);
            backend.start(stream::SweepSetup { grid: &grid, dirs: &dirs, table, layers: &layers, camera, albedo: delta.albedo }, progress)?
        };
        if let Some(jt) = j_true {
            timings.time("lpm first order", || sweeper.sweep(&u_prev, &boundary, &mut u_cur, Some(&mut j), &mut report.sweep, progress))?;
            // Non-negative up to rounding (sigma_t' <= sigma_t along every ray).
            for (a, b) in j.iter_mut().zip(&jt) {
                *a = (*a - *b).max(Vec3::ZERO);
            }
        }
        std::mem::swap(&mut u_prev, &mut u_cur);
        let first_max = max_abs(&u_prev);
        report.max_u.push(first_max);
        if !progress.update("lpm propagate", 0.1) {
            return Err(Error::Cancelled);
        }
        // The late orders' sweeper over fewer directions (coarse.rs), started when the first
        // ones are done.
        let late = if coarse_late_orders { Some(coarse::LateOrders::new(&dirs, medium.g, &delta)?) } else { None };
        let late_layers = match (&late, ov.layers) {
            (Some(_), Some(l)) => [l.max(1); FACES],
            (Some(late), None) => stream::plan(grid.dims, &late.dirs, s.memory_budget)?,
            (None, _) => layers,
        };
        timings.time("lpm propagate", || -> Result<()> {
            let mut late_sweeper: Option<Box<dyn stream::Sweeper + '_>> = None;
            // A solve of many orders ends on their geometric tail (tail.rs).
            let mut tail = coarse_late_orders.then(|| tail::Tail::new(&j));
            while first_max > 0.0 && report.orders < s.max_orders as usize && *report.max_u.last().unwrap_or(&0.0) > s.epsilon * first_max {
                if let Some(late) = late.as_ref().filter(|_| late_sweeper.is_none() && report.orders == coarse::FIRST_ORDERS) {
                    let setup = stream::SweepSetup { grid: &grid, dirs: &late.dirs, table: late.table(), layers: &late_layers, camera, albedo: delta.albedo };
                    late_sweeper = Some(backend.start(setup, progress)?);
                    if let Some(t) = tail.as_mut() {
                        t.restart();
                    }
                }
                // The last sweep: U scaled so that it adds every order still to come.
                let tail_factor = tail.as_ref().and_then(tail::Tail::factor);
                if let Some(f) = tail_factor {
                    u_prev.iter_mut().for_each(|v| *v *= f);
                    report.tail_factor = Some(f);
                }
                u_cur.iter_mut().for_each(|v| *v = Vec3::ZERO);
                let before = ov.keep_orders.then(|| j.clone());
                match late_sweeper.as_mut() {
                    Some(late_sweeper) => {
                        let boundary = late.as_ref().map_or(&zero_boundary, |l| &l.zero_boundary);
                        late_sweeper.sweep(&u_prev, boundary, &mut u_cur, Some(&mut j), &mut report.sweep, progress)?;
                        report.coarse_orders += 1;
                    }
                    None => sweeper.sweep(&u_prev, &zero_boundary, &mut u_cur, Some(&mut j), &mut report.sweep, progress)?,
                }
                if let Some(b) = before {
                    report.j_per_order.push(j.iter().zip(&b).map(|(a, b)| *a - *b).collect());
                }
                report.orders += 1;
                if tail_factor.is_some() {
                    // Its U is the scaled tail's, no order's: the last order's largest U stays last.
                    break;
                }
                std::mem::swap(&mut u_prev, &mut u_cur);
                report.max_u.push(max_abs(&u_prev));
                if let Some(t) = tail.as_mut() {
                    t.push(&j);
                }
                let done = (report.orders as f32 / s.max_orders as f32).max((s.epsilon * first_max / report.max_u.last().unwrap_or(&1.0).max(1e-30)).min(1.0));
                if !progress.update("lpm propagate", 0.1 + 0.8 * done) {
                    return Err(Error::Cancelled);
                }
            }
            Ok(())
        })?;
        drop(u_prev);
        drop(u_cur);
        drop(sweeper);
        let j_grid = grid.as_scattering_grid(j);
        if ov.j_only {
            report.j = Some(j_grid);
            return Ok((SolveOutput::new(crate::lattice_product::finished(medium, single), timings), report));
        }
        let merged = Merged { j: j_grid, density: grid.density.clone() };
        let pop_like = s.upsampling();
        let mut scattering = timings.time("lpm upsample", || upsample(medium, &mip, &merged, &pop_like))?;
        debug_assert_eq!(scattering.dims, single.dims);
        for (a, b) in scattering.data.iter_mut().zip(&single.data) {
            *a += *b;
        }
        report.j = Some(merged.j);
        // Before the file is written: it holds what the solve returns.
        crate::lattice_product::finish(medium, &mut scattering);
        if let Some(path) = &self.s_vdb {
            crate::vdb::write_rgb_grids(path, "scattering", scattering.dims, &scattering.data, scattering.index_to_world, &Default::default())?;
        }
        progress.update("lpm upsample", 1.0);
        Ok((SolveOutput::new(scattering, timings), report))
    }
}

/// The single scattering's dome spacing: the dome's part on the coarsest points the stage allows
/// (`MIN_DOME_POINTS` a side), blended between. Its light varies slowly, a sun's is what
/// changes within a voxel, and a forward lobe takes up to 8x the directions.
const COARSEST_DOME: u32 = u32::MAX;

/// The output grid (its frame) and S's exact single scattering on it (the empty grid when
/// only J is asked for).
fn output_start(s: &LpmSettings, scene: &Scene, progress: &dyn Progress, ov: Overrides, timings: &mut Timings) -> Result<(crate::stages::ScatteringGrid, crate::stages::ScatteringGrid)> {
    let out_probe = crate::stages::ScatteringGrid::over_medium(&scene.medium, s.output_size())?;
    let single = if ov.j_only {
        out_probe.clone()
    } else {
        timings.time("lpm single scattering", || single_scattering_grid_dome_spaced(scene, s.output_size(), s.dome_directions_for(scene.medium.g), COARSEST_DOME, progress))?
    };
    Ok((out_probe, single))
}

/// Whether anything scatters more than once (else S is the single scattering alone).
fn scatters(scene: &Scene) -> bool {
    !scene.medium.grid.is_empty() && scene.medium.albedo.max_element() > 0.0
}

impl Solver for Lpm {
    fn name(&self) -> &'static str {
        "lpm"
    }

    /// Its collect bins the direction to the camera (collect.rs), and the phase table's rows differ
    /// in their last bits between bins even at g 0.
    fn view_independent(&self, _scene: &Scene) -> bool {
        false
    }

    /// S with what the solve did (`LpmReport`) attached; the sweeps (propagate and collect,
    /// every order) on the device's `SweepBackend` when the context carries one (out of core:
    /// on the CPU).
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let backend: &dyn stream::SweepBackend = ctx.backend::<dyn stream::SweepBackend>().unwrap_or(&stream::CpuSweeps);
        let mut counters = Counters::default();
        let (mut out, report) = self.run(scene, ctx, backend, &mut counters)?;
        out.notes.extend(report.notes.iter().cloned());
        Ok(out.with_counters(counters).with_report(report))
    }
}
