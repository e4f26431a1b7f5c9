//! `photon-grid`: temporally coherent photon beams into an HG-lobe cache (paper 04, issue 17),
//! first landing, CPU.
//!
//! Stages, one file each: photons from every light through the shared `LightSampler` (equal
//! expected flux: each ray's power is the total over the photon count), Woodcock / spectral
//! tracking with a deposit at every tentative collision (trace.rs), the cache grid with two HG
//! lobes per cell, once-scattered light and the rest (cache.rs, `SPLIT_ORDER`), and S towards the viewer (reconstruct.rs). Single scattering comes
//! from the compositor's exact `single_scattering_grid` by default (settings.rs says why).
//!
//! Not yet (issue 17): the temporal ring of partial caches in a session (every frame is a
//! one-off solve of all photons), the paper's physically based upsampling, the GPU kernel.

mod cache;
mod reconstruct;
pub mod settings;
mod trace;

#[cfg(test)]
mod tests;

pub use reconstruct::Lobe;
pub use settings::{PhotonGridSettings, Similarity, SingleScattering};
pub use trace::EnergyReport;

use crate::compositor::{dome_directions_for, single_scattering_grid, CompositeOptions};
use crate::error::{Error, Result};
use crate::medium::MajorantGrid;
use crate::scene::Scene;
use crate::solvers::{parse_settings, Progress, SolveOutput, Solver, Timings};
use crate::translate::LightSampler;

/// Light scattered fewer times than this goes into a cell's first lobe, the rest into its
/// second: two HG lobes per cell instead of the paper's one. Departure, by measurement (2^20
/// photons, cache 24, image / grid rel. RMSE): one lobe, cube g 0.9 0.152 / 0.192 and dense
/// cloud 0.203 / 0.251 (image x0.90: the inward, once-scattered sun lobe and the outward
/// diffuse flux cancel in one moment vector); split at 2, 0.134 / 0.169 and 0.153 / 0.240
/// (x0.98); at 3, cloud 0.146 but cube 0.146 (at 4). Order 2 is also the natural cut: once
/// scattered light is the medium's HG(g) about the sun, what follows is the diffuse part.
const SPLIT_ORDER: u32 = 2;

pub struct PhotonGrid {
    settings: PhotonGridSettings,
}

/// What a solve measured besides S.
#[derive(Clone, Debug, Default)]
pub struct PhotonGridReport {
    pub energy: EnergyReport,
}

impl PhotonGrid {
    pub fn new(settings: PhotonGridSettings) -> Result<Self> {
        settings.validate()?;
        Ok(PhotonGrid { settings })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        PhotonGrid::new(parse_settings(map)?)
    }

    /// Traces the photons into the cache (normalised tallies) and reports the energy.
    fn trace(&self, scene: &Scene, timings: &mut Timings) -> Result<([cache::Tallies; 2], EnergyReport)> {
        let s = &self.settings;
        let medium = &scene.medium;
        let empty = cache::Cache::new(medium, s.cache_resolution)?;
        let majorant = timings.time("majorant", || MajorantGrid::new(medium, s.majorant_resolution as i32));
        let reduced_medium = s.switch_order(medium.g).map(|_| trace::reduced_medium(medium, s.reduction(medium.g)));
        let reduced_majorant = reduced_medium.as_ref().map(|m| MajorantGrid::new(m, s.majorant_resolution as i32));
        let sampler = LightSampler::new(scene);
        let tracer = trace::Tracer {
            medium,
            majorant: &majorant,
            reduced: reduced_medium.as_ref().zip(reduced_majorant.as_ref()),
            settings: s,
            deposit_unscattered: s.single_scattering == SingleScattering::Photons,
            split_order: SPLIT_ORDER,
        };
        let (batches, energy) = timings.time("trace", || tracer.run(&sampler, &empty));
        // Deposits carry ray.power / photons already.
        let lobe = |l: usize| batches.iter().map(|b| &b[l]).collect::<Vec<_>>();
        let tallies = timings.time("cache", || [cache::Tallies::sum(medium, &lobe(0), 1.0), cache::Tallies::sum(medium, &lobe(1), 1.0)]);
        Ok((tallies, energy))
    }

    /// Solves and returns the energy report with S and the timings.
    pub fn solve_detailed(&self, scene: &Scene, progress: &dyn Progress) -> Result<(SolveOutput, PhotonGridReport)> {
        let mut timings = Timings::default();
        if !progress.update("photons", 0.0) {
            return Err(Error::Cancelled);
        }
        let (tallies, energy) = self.trace(scene, &mut timings)?;
        if !progress.update("reconstruct", 0.8) {
            return Err(Error::Cancelled);
        }
        let res = self.settings.output_resolution;
        let mut s = timings.time("reconstruct", || reconstruct::scattering_towards(&scene.medium, &tallies, scene.camera.position, res))?;
        if self.settings.single_scattering == SingleScattering::Exact {
            let dirs = dome_directions_for(scene, CompositeOptions::default().dome_directions);
            let single = timings.time("single scattering", || single_scattering_grid(scene, res, dirs))?;
            // Same medium, same max_dim: the same frame (ScatteringGrid::over_medium).
            debug_assert_eq!(single.dims, s.dims);
            for (a, b) in s.data.iter_mut().zip(&single.data) {
                *a += *b;
            }
        }
        progress.update("done", 1.0);
        Ok((SolveOutput { scattering: s, timings }, PhotonGridReport { energy }))
    }

    /// The view-independent first lobe (fluence, g', direction) at world points (light
    /// scattered less than `SPLIT_ORDER` times; in `exact` mode without the unscattered light):
    /// the cache as a host could keep it to re-light from any view.
    pub fn lobes(&self, scene: &Scene, points: &[glam::Vec3]) -> Result<Vec<Lobe>> {
        let (tallies, _) = self.trace(scene, &mut Timings::default())?;
        Ok(points.iter().map(|&p| tallies[0].lobe(p)).collect())
    }
}

impl Solver for PhotonGrid {
    fn name(&self) -> &'static str {
        "photon-grid"
    }
    fn solve(&self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
        self.solve_detailed(scene, progress).map(|(out, _)| out)
    }
}
