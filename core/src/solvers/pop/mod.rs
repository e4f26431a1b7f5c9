//! `pop`: principal-ordinates propagation (paper 01, Sec. 4) for distant lights, and radial
//! grids (Sec. 6) for point, sphere, spot and area lights (radial/, whose module doc lists its
//! own departures: equal-area octahedral map, power per cell, face-size weights, VPL clamp).
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
//!   (image rel. RMSE 3.3 and 2.6 at g 0 and 0.7, against 0.18 and 0.27 with it).
//! - light_grid.rs: cubic cells (Eq. 3's 45-degree cones assume them), so a grid is
//!   `grid_resolution` cells along its longest side rather than e.g. 64^2 x 16.
//! - negative g: the anisotropy decays with |g|^(sigma_s t) (Eq. 4 assumes g in [0, 1]).
//!
//! Local lights: each point, sphere or spot light, and each VPL of an area light, propagates in
//! its own radial grid (radial/), whose J is added into the merged grid before upsampling.
//!
//! Not here yet (later issues): proper environment lighting (importance-sampled ordinates,
//! importance propagation, isotropic residuum, Sec. 5). A dome is handled crudely but honestly: a fixed
//! set of `dome_ordinates` distant ordinates, each with its cell's mean radiance and the
//! prefiltered anisotropy of Sec. 5.1; energy is right, the angular detail of a map is not.

pub mod accumulate;
pub mod init;
pub mod light_grid;
pub mod merge;
pub mod mip;
pub mod propagate;
pub mod radial;
pub mod settings;
pub mod upsample;

use glam::Vec3;

use super::{parse_settings, Progress, ScatteringGrid, SolveOutput, Solver, Timings};
use crate::error::{Error, Result};
use crate::scene::{Light, Scene};
use light_grid::LightGrid;
use mip::MediumMip;
pub use propagate::PropagationStats;
pub use settings::PopSettings;

/// One light's propagation: adds the accumulated in-scattered radiance into `j_acc` and
/// returns the energy figures, as `propagate::Propagation::run_with` does.
pub type PropagateFn<'a> = dyn Fn(&propagate::Propagation, propagate::RunOptions, &init::Initial, f32, &mut [Vec3], &dyn Progress) -> Result<PropagationStats>
    + Sync
    + 'a;

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

#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PopReport {
    pub lights: Vec<LightReport>,
    /// Local lights' radial grids (radial/), in W.
    pub radial: Vec<radial::RadialReport>,
    pub warnings: Vec<String>,
}

impl Pop {
    pub fn new(settings: PopSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Pop { settings })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Pop::new(parse_settings(map)?)
    }

    /// Solves and returns the per-light energy report along with S and the timings.
    pub fn solve_detailed(&self, scene: &Scene, progress: &dyn Progress) -> Result<(SolveOutput, PopReport)> {
        self.solve_with(scene, progress, &|prop, opts, init, a, j, progress| prop.run_with(opts, init, a, j, progress))
    }

    /// As `solve_detailed`, with each light's propagation (the costly stage) run by
    /// `propagate`: the CPU's `Propagation::run_with`, or a GPU port (volscatter-gpu).
    pub fn solve_with(&self, scene: &Scene, progress: &dyn Progress, propagate: &PropagateFn) -> Result<(SolveOutput, PopReport)> {
        self.solve_with_backends(scene, progress, propagate, &radial::cpu_propagate)
    }

    /// As `solve_with`, with the radial grids' propagation run by `radial_propagate`.
    pub fn solve_with_backends(
        &self,
        scene: &Scene,
        progress: &dyn Progress,
        propagate: &PropagateFn,
        radial_propagate: &radial::RadialPropagateFn,
    ) -> Result<(SolveOutput, PopReport)> {
        let s = &self.settings;
        let medium = &scene.medium;
        let mut timings = Timings::default();
        let mut report = PopReport::default();
        // Every light becomes ordinates: (direction of travel, fluence, initial anisotropy,
        // grid resolution).
        let mut distant: Vec<(Vec3, Vec3, f32, u32)> = Vec::new();
        for (i, light) in scene.lights.iter().enumerate() {
            match light {
                Light::Distant { direction, irradiance, half_angle } => {
                    // A disc of angular radius theta and irradiance E (perpendicular): fluence
                    // E * 2 / (1 + cos theta), mean cosine (1 + cos theta) / 2 = initial
                    // anisotropy.
                    let one_minus_cos = 2.0 * (0.5 * half_angle).sin().powi(2);
                    let fluence = *irradiance * (2.0 / (2.0 - one_minus_cos));
                    distant.push((*direction, fluence, 1.0 - 0.5 * one_minus_cos, s.grid_resolution));
                }
                Light::Dome(env) if s.dome_ordinates > 0 => {
                    for (d, fluence, a0) in dome_ordinates(env, s.dome_ordinates) {
                        distant.push((d, fluence, a0, s.dome_grid_resolution()));
                    }
                }
                // Local lights: radial grids, below.
                Light::Point { .. } | Light::Spot(_) | Light::Area(_) => {}
                Light::Dome(_) => report.warnings.push(format!(
                    "pop: lights[{i}] is a dome and dome_ordinates = 0: its light is left out of the scattering (the compositor still shows it behind the medium)"
                )),
            }
        }
        for w in &report.warnings {
            eprintln!("warning: {w}");
        }
        let local = radial::sources(&scene.lights, s.area_vpls);
        if distant.is_empty() && local.is_empty() {
            return Err(Error::InvalidArgument("pop: the scene has no light pop can propagate (distant, dome with ordinates, point, spot or area)".into()));
        }
        if !progress.update("pop setup", 0.0) {
            return Err(Error::Cancelled);
        }

        // The finest footprint asked of the mip: the output grid's spacing or the light grids'
        // cells, whichever is smaller.
        let out_probe = ScatteringGrid::over_medium(medium, s.output_resolution)?;
        let merge_probe = ScatteringGrid::over_medium(medium, s.merge_resolution())?;
        let (wlo, whi) = medium.world_bounds();
        let cell_guess = (whi - wlo).max_element() / s.grid_resolution as f32 / medium.voxel_size_world().max_element();
        let min_fp = merge::footprint(medium, &out_probe).min(merge::footprint(medium, &merge_probe)).min(cell_guess);
        let mip = timings.time("pop mip", || MediumMip::new(medium, min_fp));

        let g = medium.g;
        let mut lights = Vec::with_capacity(distant.len());
        for (direction, fluence, a0, resolution) in distant {
            if fluence.max_element() <= 0.0 {
                continue;
            }
            let grid = timings.time("pop light grid", || LightGrid::new(medium, &mip, direction, resolution))?;
            let init = timings.time("pop init", || init::sweep(&grid, fluence));
            let mut j_acc = vec![Vec3::ZERO; grid.len()];
            let mu = accumulate::view_cosines(&grid, scene.camera.position);
            accumulate::add_direct(&init.direct, &mu, a0, g, &mut j_acc);
            let prop = propagate::Propagation {
                grid: &grid,
                g,
                mu: &mu,
                diffusion_correction: s.diffusion_correction,
                max_iterations: s.max_iterations,
                residual_threshold: s.residual_threshold,
            };
            let t0 = std::time::Instant::now();
            let opts = propagate::RunOptions { vacuum_escape: s.vacuum_escape };
            let stats = propagate(&prop, opts, &init, a0 * g, &mut j_acc, progress)?;
            timings.0.push(("pop propagation".into(), t0.elapsed().as_secs_f64()));
            report.lights.push(LightReport {
                dims: grid.dims.to_array(),
                cell_size: grid.h,
                entering: init.entering.to_array(),
                transmitted: init.transmitted.to_array(),
                absorbed_direct: init.absorbed.to_array(),
                propagation: stats,
            });
            lights.push((grid, j_acc));
        }
        let mut merged = timings.time("pop merge", || merge::merge(medium, &mip, &lights, s.merge_resolution()))?;
        // --- local lights (radial/) ---
        let merged_spacing = radial::spacing(&merged.j);
        let (radial_lights, radial_reports) = radial::solve_sources(scene, &mip, s, merged_spacing, &local, progress, radial_propagate, &mut timings)?;
        timings.time("pop merge", || radial::add_to_merged(&mut merged.j, &radial_lights));
        report.radial = radial_reports;
        // --- end local lights ---
        if !progress.update("pop upsample", 0.0) {
            return Err(Error::Cancelled);
        }
        let scattering = timings.time("pop upsample", || upsample::upsample(medium, &mip, &merged, s))?;
        progress.update("pop upsample", 1.0);
        Ok((SolveOutput { scattering, timings: merge_timings(timings) }, report))
    }
}

/// Directions of `n` points spread evenly over the sphere (Fibonacci lattice).
fn fibonacci_sphere(n: u32) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// A dome as `n` ordinates: (direction of travel, fluence, initial anisotropy). Each ordinate
/// owns the directions nearest to it (solid angle ~ 4 pi / n); its fluence is the mean radiance
/// over them (2048 probe directions) times the solid angle, so the total equals the dome's
/// fluence exactly for a uniform colour. Anisotropy: the mean cosine of a cone of that solid
/// angle, 1 - 1/n (Sec. 5.1's prefiltering).
fn dome_ordinates(env: &crate::scene::Environment, n: u32) -> Vec<(Vec3, Vec3, f32)> {
    let dirs = fibonacci_sphere(n);
    let probes = fibonacci_sphere(2048);
    let mut sum = vec![Vec3::ZERO; dirs.len()];
    for p in &probes {
        let k = (0..dirs.len()).max_by(|&a, &b| dirs[a].dot(*p).total_cmp(&dirs[b].dot(*p))).unwrap();
        sum[k] += env.radiance(*p);
    }
    let omega = 4.0 * std::f32::consts::PI / probes.len() as f32;
    // Light arriving from direction w (towards the sky) travels along -w.
    dirs.iter().zip(sum).map(|(w, s)| (-*w, s * omega, 1.0 - 1.0 / n as f32)).collect()
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

impl Solver for Pop {
    fn name(&self) -> &'static str {
        "pop"
    }
    fn solve(&self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
        self.solve_detailed(scene, progress).map(|(out, _)| out)
    }
}

#[cfg(test)]
mod tests;
