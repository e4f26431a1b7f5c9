//! `network`: illumination networks (paper 02, Szirmay-Kalos et al.), CPU, first landing.
//!
//! Stages, one file each: particles sampled in proportion to sigma_t, each a ball sized from
//! its density (particles.rs); D Fibonacci directions and the row-normalised HG phase matrix
//! (directions.rs); the visibility network, per direction an M x M orthographic window sorted
//! by depth giving each particle its upstream neighbour and the pair's ray-marched opacity
//! (visibility.rs); the direct light's first scattering, exact (direct.rs); the iteration of
//! Eq. 2 to a residual (iterate.rs); the particles' radiance towards the viewer splatted to the
//! grid times sigma_s (splat.rs). The result is S = (the compositor's exact single scattering)
//! + sigma_s x (the network's scattered light towards the viewer).
//!
//! Departures from the paper, each where it is made: opacity from ray-marched optical depth
//! (visibility.rs), direct light exact and outside the network (direct.rs), sweeps instead of
//! Jacobi steps (iterate.rs), HG instead of Cornette-Shanks with rows normalised
//! (directions.rs), grid splatting instead of camera-facing splats (splat.rs).
//!
//! Not yet here (issue 18): warm start in a session and re-splatting on a camera move, the GPU
//! backend.

mod direct;
mod directions;
mod iterate;
mod particles;
pub mod settings;
mod splat;
mod visibility;
#[cfg(test)]
mod tests;

pub use settings::NetworkSettings;

use super::{parse_settings, Progress, SolveOutput, Solver, Timings};
use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::translate::sampling::BoundingSphere;

pub struct Network {
    settings: NetworkSettings,
}

/// What a solve measured, for tests and benchmarks.
#[derive(Clone, Debug)]
pub struct NetworkReport {
    pub window: u32,
    /// Residual after each iteration.
    pub residuals: Vec<f64>,
}

impl Network {
    pub fn new(settings: NetworkSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Network { settings })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Network::new(parse_settings(map)?)
    }

    /// Solves and returns what the iteration did along with S and the timings.
    pub fn solve_detailed(&self, scene: &Scene, progress: &dyn Progress) -> Result<(SolveOutput, NetworkReport)> {
        let s = &self.settings;
        let medium = &scene.medium;
        let mut timings = Timings::default();
        let mut scattering = timings.time("network single scattering", || {
            crate::compositor::single_scattering_grid(scene, s.output_resolution, s.dome_directions)
        })?;
        let mut report = NetworkReport { window: 0, residuals: Vec::new() };
        if medium.grid.is_empty() || medium.albedo.max_element() <= 0.0 {
            // Nothing scatters twice: S is its single scattering.
            return Ok((SolveOutput { scattering, timings }, report));
        }
        // Radiance, source, first-scattering and visibility arrays: ~4 RGB values per
        // (particle, direction) pair.
        crate::budget::check_elements::<[glam::Vec3; 4]>("network arrays (solver.particles x solver.directions)", s.particles as u64 * s.directions as u64)?;
        let p = timings.time("network particles", || particles::sample(medium, s.particles, s.seed));
        if p.mean_sigma_t <= 0.0 {
            return Ok((SolveOutput { scattering, timings }, report));
        }
        let dirs = directions::fibonacci(s.directions);
        let sphere = BoundingSphere::of(medium);
        report.window = visibility::window_side(s.window, s.directions, sphere.radius, p.mean_sigma_t, p.len());
        let links = timings.time("network visibility", || visibility::build(medium, &p, &dirs, sphere.center, sphere.radius, report.window, s.opacity));
        if !progress.update("network visibility", 0.3) {
            return Err(Error::Cancelled);
        }
        let first = timings.time("network direct", || direct::first_scattering(scene, &p, &dirs, s.dome_directions));
        let phase = directions::phase_matrix(&dirs, medium.g);
        let it = timings.time("network iterate", || {
            iterate::iterate(&links, &phase, &first, medium.albedo, s.max_iterations, s.residual_threshold, None)
        });
        report.residuals = it.residuals;
        if !progress.update("network iterate", 0.9) {
            return Err(Error::Cancelled);
        }
        timings.time("network splat", || {
            let values = splat::towards_viewer(&p, &it.radiance, &dirs, medium.g, scene.camera.position);
            splat::splat_into(&mut scattering, medium, &p, &values, s.kernel_radius, s.range_sigma);
        });
        progress.update("network splat", 1.0);
        Ok((SolveOutput { scattering, timings }, report))
    }
}

impl Solver for Network {
    fn name(&self) -> &'static str {
        "network"
    }

    fn solve(&self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
        Ok(self.solve_detailed(scene, progress)?.0)
    }
}
