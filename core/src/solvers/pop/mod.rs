//! `pop`: principal-ordinates propagation (paper 01, Sec. 4-6) for distant lights, domes, and,
//! through radial grids (Sec. 6), point, sphere, spot and area lights (radial/, whose module doc
//! lists its own departures: equal-area octahedral map, power per cell, face-size weights, VPL
//! clamp).
//!
//! Pipeline per distant light: a propagation grid aligned with the light (light_grid.rs) over
//! a mip-prefiltered copy of the medium (mip.rs); a transmittance sweep that gives the exact
//! unscattered light and the energy it scatters (init.rs); propagation of that energy by
//! Eq. 1-6 with ping-pong grids until the residual is small (propagate.rs), accumulating the
//! view-dependent in-scattered radiance (accumulate.rs, Eq. 7-8). Then all lights are merged
//! into one medium-aligned grid (merge.rs) and upsampled to the output grid by a joint
//! bilateral filter guided by the density (upsample.rs), which gives the scattering grid S.
//!
//! Departures from the paper, each explained where it is made:
//! - init.rs: the unscattered light is computed exactly (sweep with full extinction) and only
//!   the energy it loses to scattering is propagated; the paper's literal "initialise every
//!   cell with L_in T_i, move it all, accumulate every iteration" counts the beam once per
//!   upstream cell.
//! - accumulate.rs: the accumulation holds the light scattered towards the camera,
//!   f_hg(mu, a g) (HG self-convolution), not the radiance travelling towards it, f_hg(mu, a).
//! - propagate.rs: an iteration stands for a light path matched to the lattice's drift
//!   (directional light) and to physical diffusion (isotropic light) instead of one cell edge;
//!   without it diffuse light is several times too bright on the paper's own Fig. 12 cube
//!   (docs/solvers/pop.md).
//! - light_grid.rs: cubic cells (Eq. 3's 45-degree cones assume them), so a grid is
//!   `grid_resolution` cells along its longest side rather than e.g. 64^2 x 16.
//! - negative g: the anisotropy decays with |g|^(sigma_s t) (Eq. 4 assumes g in [0, 1]).
//! - `moment_anisotropy` (opt-in, propagate.rs `lobe_moments`): the parts of a lobe sent
//!   front, sideways and back leave with their own cones' mean cosines instead of the lobe's a
//!   (Eq. 5-6 re-aim light sent back along d); docs/pop-dense-clouds.md has the diagnosis on
//!   the dense cloud that led to it and why it is not the default.
//!
//! Environment lighting (Sec. 5): a dome becomes `dome_ordinates` distant ordinates, the
//! sphere cut into regions of equal importance, each ordinate carrying exactly its region's
//! light with its radiance-weighted mean cosine as initial anisotropy (translate/dome.rs,
//! Sec. 5.1); the importance is the dome's luminance times a directional importance map
//! propagated from the camera (importance.rs, Sec. 5.2). With `isotropic_residuum`, every light (distant or
//! dome ordinate) stops at its switch iteration m' (Eq. 10) and the energy still travelling in
//! all of them is propagated isotropically in one medium-aligned grid (residuum.rs, Sec. 5.4),
//! with the same backend as the lights (CPU or GPU).
//!
//! Local lights: each point, sphere or spot light, and each VPL of an area light, propagates in
//! its own radial grid (radial/), whose J is added into the merged grid before upsampling.
//!
//! In a session (pipeline/session.rs), what the medium, the camera and an ordinate alone decide
//! is kept between frames and reused while it still applies (reuse.rs).

pub mod accumulate;
pub mod backend;
pub mod importance;
pub mod init;
pub mod light_grid;
pub mod merge;
pub mod propagate;
pub mod radial;
pub mod residuum;
pub mod reuse;
pub mod settings;

use glam::Vec3;

use super::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Progress, ScatteringGrid, Timings};
use crate::error::{Error, Result};
use crate::scene::{Light, Scene};
use crate::translate::{distant_ordinate, dome};
use backend::PopBackend;
use light_grid::LightGrid;
use crate::stages::mip::MediumMip;
use crate::stages::upsample::footprint;
pub use propagate::PropagationStats;
pub use settings::PopSettings;

pub struct Pop {
    pub settings: PopSettings,
}

/// Energy bookkeeping of one light, per unit cell cross-section of its grid (W/m^2 x cells),
/// RGB. `entering` = `transmitted` + `absorbed_direct` + `propagation.injected`, and
/// `injected` = `escaped` + `absorbed` + `residual`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LightReport {
    pub dims: [u32; 3],
    pub cell_size: f32,
    pub entering: [f32; 3],
    pub transmitted: [f32; 3],
    pub absorbed_direct: [f32; 3],
    pub propagation: PropagationStats,
}

impl LightReport {
    /// (light leaving the medium + light absorbed) / light entering, per channel. 1 means
    /// energy is conserved; the dropped residual counts as lost.
    pub fn energy_balance(&self) -> [f32; 3] {
        std::array::from_fn(|c| {
            let out = self.transmitted[c] + self.absorbed_direct[c] + self.propagation.escaped[c] + self.propagation.absorbed[c];
            if self.entering[c] > 0.0 { out / self.entering[c] } else { 1.0 }
        })
    }
}

/// The isotropic residuum's figures (residuum.rs), per unit cell cross-section of its grid.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ResiduumReport {
    pub dims: [u32; 3],
    pub cell_size: f32,
    /// The lights' energy still travelling when they switched, gathered here
    /// (= `propagation.injected`).
    pub gathered: [f32; 3],
    pub propagation: PropagationStats,
}

#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PopReport {
    pub lights: Vec<LightReport>,
    /// Present when the isotropic residuum ran.
    pub residuum: Option<ResiduumReport>,
    /// Local lights' radial grids (radial/), in W.
    pub radial: Vec<radial::RadialReport>,
    pub warnings: Vec<String>,
}

impl PopReport {
    /// Energy balance of the whole solve in watts (each grid's figures times its cell
    /// cross-section): (light leaving + absorbed) / light entering, per channel. With the
    /// residuum, what the lights hand over is counted where it finally goes.
    pub fn energy_balance(&self) -> [f32; 3] {
        let (mut entering, mut out) = (Vec3::ZERO, Vec3::ZERO);
        for l in &self.lights {
            let area = l.cell_size * l.cell_size;
            entering += Vec3::from(l.entering) * area;
            let p = &l.propagation;
            out += (Vec3::from(l.transmitted) + Vec3::from(l.absorbed_direct) + Vec3::from(p.escaped) + Vec3::from(p.absorbed)) * area;
        }
        if let Some(r) = &self.residuum {
            out += (Vec3::from(r.propagation.escaped) + Vec3::from(r.propagation.absorbed)) * r.cell_size * r.cell_size;
        }
        std::array::from_fn(|c| if entering[c] > 0.0 { out[c] / entering[c] } else { 1.0 })
    }

    /// Propagation work: cell updates summed over every grid (cells x iterations), the
    /// measure of cost the residuum saves.
    pub fn cell_updates(&self) -> u64 {
        let cells = |d: [u32; 3]| d[0] as u64 * d[1] as u64 * d[2] as u64;
        self.lights.iter().map(|l| cells(l.dims) * l.propagation.iterations as u64).sum::<u64>()
            + self.residuum.as_ref().map_or(0, |r| cells(r.dims) * r.propagation.iterations as u64)
    }
}

impl Pop {
    pub fn new(settings: PopSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Pop { settings })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Pop::new(parse_settings(map)?)
    }

    /// The solve on `backend` (the CPU's, or a device's through `PopDevice`), one frame of a
    /// session when `reuse` is given: the light-independent stages then come from it when the
    /// medium (and camera) they were made for did not change (reuse.rs).
    fn run<B: PopBackend>(&self, scene: &Scene, progress: &dyn Progress, backend: &B, mut reuse: Option<&mut reuse::PopReuse>) -> Result<(SolveOutput, PopReport)> {
        let s = &self.settings;
        let medium = &scene.medium;
        let mut timings = Timings::default();
        let mut report = PopReport::default();
        // The finest footprint asked of the mip: the output grid's spacing or the light grids'
        // cells, whichever is smaller.
        let out_probe = ScatteringGrid::over_medium(medium, s.output_resolution)?;
        let merge_probe = ScatteringGrid::over_medium(medium, s.merge_resolution())?;
        let (wlo, whi) = medium.world_bounds();
        let cell_guess = (whi - wlo).max_element() / s.grid_resolution as f32 / medium.voxel_size_world().max_element();
        let min_fp = footprint(medium, &out_probe).min(footprint(medium, &merge_probe)).min(cell_guess);
        // In a session, the medium's key decides what may be reused (one pass over its voxels).
        let key = reuse.is_some().then(|| timings.time("pop medium key", || crate::medium::key::MediumKey::of(medium)));
        let mip = timings.time("pop mip", || match (reuse.as_deref_mut(), &key) {
            (Some(r), Some(k)) => r.mip(k, medium, min_fp),
            _ => std::sync::Arc::new(MediumMip::new(medium, min_fp)),
        });

        // Every light becomes ordinates (translate/ordinates.rs, translate/dome.rs): (direction
        // of travel, fluence, initial anisotropy, grid resolution).
        let mut distant: Vec<(Vec3, Vec3, f32, u32)> = Vec::new();
        for (i, light) in scene.lights.iter().enumerate() {
            match light {
                Light::Distant { direction, irradiance, half_angle } => {
                    let o = distant_ordinate(*direction, *irradiance, *half_angle);
                    distant.push((o.direction, o.fluence, o.a0, s.grid_resolution));
                }
                Light::Dome(env) if s.dome_ordinates > 0 => {
                    let weights = if s.dome_importance {
                        let build = || importance::directional_importance(medium, &mip, &scene.camera, s.diffusion_correction, progress);
                        Some(timings.time("pop importance", || match (reuse.as_deref_mut(), &key) {
                            (Some(r), Some(k)) => r.importance(k, scene.camera.position, s.diffusion_correction, build),
                            _ => build().map(std::sync::Arc::new),
                        })?)
                    } else {
                        None
                    };
                    for o in dome::select_ordinates(env, s.dome_ordinates, weights.as_deref()) {
                        distant.push((o.direction, o.fluence, o.a0, s.dome_grid_resolution()));
                    }
                }
                // Local lights: radial grids, below.
                Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
                Light::Dome(_) => report.warnings.push(format!(
                    "pop: lights[{i}] is a dome and dome_ordinates = 0: its light is left out of the scattering (the compositor still shows it behind the medium)"
                )),
            }
        }
        // The cost guard: a radial grid per source, so thousands of the scene's are merged
        // (radial/cluster.rs); the emission VPLs are as many as the settings ask for.
        let (mlo, mhi) = medium.world_bounds();
        let (mut local, merged_note) = radial::cluster::cluster(radial::sources(&scene.lights, s.area_vpls), radial::cluster::MAX_SOURCES, |p| p.cmpge(mlo).all() && p.cmple(mhi).all());
        report.warnings.extend(merged_note);
        local.extend(radial::emission_sources(medium, s.emission_vpls, scene.lights.len()));
        // No light: black, as every other solver returns (the merge of no lights is zero).
        if !progress.update("pop setup", 0.0) {
            return Err(Error::Cancelled);
        }

        let g = medium.g;
        let mut lights = Vec::with_capacity(distant.len() + 1);
        let mut residuum = if s.isotropic_residuum { Some(residuum::Residuum::new(medium, &mip, s.residuum_grid_resolution(), progress)?) } else { None };
        // In a session, lights solved for this medium, camera and settings are reused (reuse.rs).
        let mut kept = match (reuse, &key) {
            (Some(r), Some(k)) => {
                r.begin_lights(k, scene.camera.position, s);
                Some(r)
            }
            _ => None,
        };
        for (direction, fluence, a0, resolution) in distant {
            // Each ordinate's grid and sweep take a core tenths of a second at high resolutions.
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            if fluence.max_element() <= 0.0 {
                continue;
            }
            let okey = reuse::OrdinateKey::new(direction, fluence, a0, resolution);
            if let Some(r) = kept.as_deref_mut() {
                if let Some((grid, light, rep)) = timings.time("pop reused lights", || r.reuse_light(&okey, backend, residuum.as_mut())) {
                    report.lights.push(rep);
                    lights.push((grid, light));
                    continue;
                }
            }
            let grid = timings.time("pop light grid", || LightGrid::new_or_cancel(medium, &mip, direction, resolution, progress))?;
            let mu = accumulate::view_cosines(&grid, scene.camera.position);
            let (mut light, sweep) = timings.time("pop init", || backend.init(&grid, fluence, &mu, a0, g, progress))?;
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            // With the residuum, each light stops at its switch iteration m' (Eq. 10).
            let max_iterations = match &residuum {
                Some(_) if s.residuum_iterations > 0 => s.residuum_iterations.min(s.max_iterations),
                Some(_) => residuum::switch_iteration(a0 * g, g, residuum::mean_sigma_s(&grid), grid.h, s.residuum_anisotropy, grid.dims.z, s.max_iterations),
                None => s.max_iterations,
            };
            let prop = propagate::Propagation {
                grid: &grid,
                g,
                mu: &mu,
                diffusion_correction: s.diffusion_correction,
                max_iterations,
                residual_threshold: s.residual_threshold,
            };
            let t0 = std::time::Instant::now();
            let opts = propagate::RunOptions { vacuum_escape: s.vacuum_escape, keep_remaining: residuum.is_some(), moment_anisotropy: s.moment_anisotropy };
            let mut stats = backend.propagate(&mut light, &prop, opts, a0 * g, progress)?;
            let remaining = std::mem::take(&mut stats.remaining);
            if let Some(r) = residuum.as_mut() {
                r.gather(&grid, &remaining);
            }
            timings.0.push(("pop propagation".into(), t0.elapsed().as_secs_f64()));
            let rep = LightReport {
                dims: grid.dims.to_array(),
                cell_size: grid.h,
                entering: sweep.entering.to_array(),
                transmitted: sweep.transmitted.to_array(),
                absorbed_direct: sweep.absorbed.to_array(),
                propagation: stats,
            };
            if let Some(r) = kept.as_deref_mut() {
                timings.time("pop reused lights", || r.keep_light(okey, backend, &grid, &light, &rep, remaining));
            }
            report.lights.push(rep);
            lights.push((grid, light));
        }
        if let Some(r) = kept {
            r.end_lights();
        }
        // The residuum runs only when the lights handed over more than the residual threshold
        // of all the energy they scattered, and iterates until what is left falls below that
        // same absolute amount (the paper's epsilon_L over all grids): a light that converged
        // before its switch hands over a negligible rest that needs no grid of its own.
        let scattered = report.lights.iter().map(|l| Vec3::from(l.propagation.injected) * l.cell_size * l.cell_size).sum::<Vec3>();
        if let Some(r) = residuum.filter(|r| (r.gathered() * r.grid.h * r.grid.h).cmpgt(scattered * s.residual_threshold).any()) {
            let t0 = std::time::Instant::now();
            let threshold = (scattered * s.residual_threshold / (r.gathered() * r.grid.h * r.grid.h).max(Vec3::splat(1e-30))).max_element().min(1.0);
            let (grid, light, rep) = run_residuum(r, scene, s, threshold, progress, backend)?;
            timings.0.push(("pop residuum".into(), t0.elapsed().as_secs_f64()));
            report.residuum = Some(rep);
            lights.push((grid, light));
        }
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let mut merged = timings.time("pop merge", || backend.merge(medium, &mip, &lights, s.merge_resolution()))?;
        // --- local lights (radial/) ---
        let merged_spacing = radial::spacing(backend.merged_grid(&merged));
        let radial_propagate: &radial::RadialPropagateFn = &|prop, init, j, progress| backend.propagate_radial(prop, init, j, progress);
        let (radial_lights, radial_reports) = radial::solve_sources(scene, &mip, s, merged_spacing, &local, progress, radial_propagate, &mut timings)?;
        timings.time("pop merge", || backend.add_radial(&mut merged, &radial_lights))?;
        report.radial = radial_reports;
        // --- end local lights ---
        if !progress.update("pop upsample", 0.0) {
            return Err(Error::Cancelled);
        }
        let scattering = timings.time("pop upsample", || backend.upsample(medium, &mip, &merged, s))?;
        progress.update("pop upsample", 1.0);
        Ok((SolveOutput::new(crate::lattice_product::finished(medium, scattering), merge_timings(timings)), report))
    }
}

/// Propagates the gathered residuum isotropically (a = 0) with the same backend as the lights,
/// to convergence; returns its grid and light (J) for merging.
fn run_residuum<B: PopBackend>(
    r: residuum::Residuum,
    scene: &Scene,
    s: &PopSettings,
    residual_threshold: f32,
    progress: &dyn Progress,
    backend: &B,
) -> Result<(LightGrid, B::Light, ResiduumReport)> {
    let grid = r.grid;
    let gathered = r.packets.iter().copied().sum::<Vec3>();
    let mu = accumulate::view_cosines(&grid, scene.camera.position);
    let mut light = backend.with_packets(&grid, r.packets, &mu)?;
    let prop = propagate::Propagation {
        grid: &grid,
        g: scene.medium.g,
        mu: &mu,
        diffusion_correction: s.diffusion_correction,
        max_iterations: s.max_iterations,
        residual_threshold,
    };
    let opts = propagate::RunOptions { vacuum_escape: s.vacuum_escape, keep_remaining: false, moment_anisotropy: s.moment_anisotropy };
    let stats = backend.propagate(&mut light, &prop, opts, 0.0, progress)?;
    let rep = ResiduumReport { dims: grid.dims.to_array(), cell_size: grid.h, gathered: gathered.to_array(), propagation: stats };
    Ok((grid, light, rep))
}

/// Sums repeated phases (one entry per light) into one entry each, keeping the order.
fn merge_timings(t: Timings) -> Timings {
    let mut out: Vec<(String, f64)> = Vec::new();
    for (k, v) in t.0 {
        match out.iter_mut().find(|(n, _)| *n == k) {
            Some(e) => e.1 += v,
            None => out.push((k, v)),
        }
    }
    Timings(out)
}

/// A `PopBackend` as a device's entry in a `SolveCtx` carries it: the backend's associated
/// types make `PopBackend` itself unfit for a trait object, so a device hands this instead
/// (every `PopBackend` is one).
pub trait PopDevice: Sync {
    fn solve(&self, pop: &Pop, scene: &Scene, progress: &dyn Progress, reuse: Option<&mut reuse::PopReuse>) -> Result<(SolveOutput, PopReport)>;
}

impl<B: PopBackend> PopDevice for B {
    fn solve(&self, pop: &Pop, scene: &Scene, progress: &dyn Progress, reuse: Option<&mut reuse::PopReuse>) -> Result<(SolveOutput, PopReport)> {
        pop.run(scene, progress, self, reuse)
    }
}

impl Solver for Pop {
    fn name(&self) -> &'static str {
        "pop"
    }

    /// Its importance and its merge weigh ordinates by the view (accumulate.rs `view_cosines`) at any g.
    fn view_independent(&self, _scene: &Scene) -> bool {
        false
    }

    /// S with the per-light energy report (`PopReport`) attached; on the device's backend when
    /// the context carries one, reusing the session's kept stages when it is a session.
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let device: &dyn PopDevice = ctx.backend::<dyn PopDevice>().unwrap_or(&backend::CpuBackend);
        let progress = ctx.progress();
        let before = ctx.session().map(|state| state.kept(reuse::PopReuse::default).counts);
        let reuse = ctx.session().map(|state| state.kept(reuse::PopReuse::default));
        let (mut out, report) = device.solve(self, scene, progress, reuse)?;
        out.notes.extend(report.warnings.iter().cloned());
        // The session's reuse counts across this frame, as the frame's counters.
        if let (Some(b), Some(a)) = (before, ctx.session().map(|state| state.kept(reuse::PopReuse::default).counts)) {
            let stages = [
                ("pop mip", a.mip_reused - b.mip_reused, a.mip_built - b.mip_built),
                ("pop importance", a.importance_reused - b.importance_reused, a.importance_built - b.importance_built),
                ("pop ordinate", a.lights_reused - b.lights_reused, a.lights_solved - b.lights_solved),
            ];
            for (stage, kept, built) in stages {
                (0..kept).for_each(|_| out.counters.kept(stage));
                (0..built).for_each(|_| out.counters.computed(stage));
            }
        }
        Ok(out.with_report(report))
    }
}

#[cfg(test)]
pub(crate) mod tests;
