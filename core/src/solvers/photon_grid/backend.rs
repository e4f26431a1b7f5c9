//! Where `photon-grid` runs its heavy stages: the tracing (every photon's Woodcock tracking
//! with a deposit at each tentative collision) and exact single scattering go through a
//! `PhotonBackend`, the CPU code (`CpuBackend`: trace.rs, the compositor) or the GPU port in
//! volscatter-gpu, and so does the reconstruction (S at the output resolution from the
//! cache's tallies, reconstruct.rs), which visits 8 or 27 cells per output voxel and lobe. The
//! rest (the ring of generations in integers, the cache's mass) stays with the solver: it is
//! linear in cells.

use rayon::prelude::*;

use glam::Vec3;

use super::cache::{Cache, Tallies};
use super::reconstruct::scattering_towards;
use super::ring::{self, Generation};
use super::settings::PhotonGridSettings;
use super::trace::Tracer;
use crate::stages::single_scattering::single_scattering_grid_cancellable;
use crate::error::Result;
use crate::medium::Medium;
use crate::scene::Scene;
use crate::stages::{Progress, ScatteringGrid};
use crate::translate::LightSampler;

/// What tracing a generation needs: the tracer (media, majorants, settings, lobe split,
/// progress), the lights, the cache's (empty) frame.
pub struct TraceJob<'a> {
    pub tracer: &'a Tracer<'a>,
    pub sampler: &'a LightSampler<'a>,
    pub empty: &'a Cache,
}

impl TraceJob<'_> {
    /// Photons of generation `g` (ring.rs `photons_of`).
    pub fn photons_of(&self, g: u64) -> u32 {
        let s = self.tracer.settings;
        ring::photons_of(g, s.photons, s.generations)
    }
}

pub trait PhotonBackend: Sync {
    /// Traces `generations` (ring.rs), returned in the order given. A cancelled trace may
    /// return cut-short generations: the caller checks `progress` and discards them.
    fn trace_generations(&self, job: &TraceJob, generations: &[u64]) -> Result<Vec<Generation>>;

    /// Exact single scattering (`SingleScattering::Exact`): the compositor's grid at
    /// `resolution` with `dome_directions`, on the CPU unless the backend has its own.
    fn single_scattering(&self, scene: &Scene, resolution: u32, dome_directions: u32, progress: &dyn Progress) -> Result<ScatteringGrid> {
        single_scattering_grid_cancellable(scene, resolution, dome_directions, progress)
    }

    /// S towards `camera` from the cache's `tallies` (one per lobe, the ring's sum) on
    /// `ScatteringGrid::over_medium(medium, settings.output_resolution)`, upsampled by
    /// `settings.upsampling` (reconstruct.rs `scattering_towards`), on the CPU unless the
    /// backend has its own. Returns `Cancelled` when `progress` is cancelled.
    fn reconstruct(&self, medium: &Medium, tallies: &[Tallies], camera: Vec3, settings: &PhotonGridSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
        scattering_towards(medium, tallies, camera, settings.output_resolution, settings.upsampling, progress)
    }
}

/// Tracing on the CPU (trace.rs), the generations in parallel.
pub struct CpuBackend;

impl PhotonBackend for CpuBackend {
    fn trace_generations(&self, job: &TraceJob, generations: &[u64]) -> Result<Vec<Generation>> {
        let total = job.tracer.settings.photons;
        Ok(generations
            .par_iter()
            .map(|&g| {
                let (tallies, energy) = job.tracer.run_generation(job.sampler, job.empty, g, job.photons_of(g), total);
                Generation { index: g, tallies, energy }
            })
            .collect())
    }
}
