//! `photon-grid`: temporally coherent photon beams into an HG-lobe cache (paper 04, issue 17),
//! first landing, CPU.
//!
//! Stages, one file each: photons from every light through the shared `LightSampler` (equal
//! expected flux: each ray's power is the total over the photon count), Woodcock / spectral
//! tracking with a deposit at every tentative collision (trace.rs), the cache grid with two HG
//! lobes per cell, once-scattered light and the rest (cache.rs, `SPLIT_ORDER`), and S towards the viewer (reconstruct.rs). Single scattering comes
//! from the compositor's exact `single_scattering_grid` by default (settings.rs says why).
//!
//! The temporal ring of partial caches (ring.rs) keeps m generations of photons in a session,
//! summed in fixed point (fixed.rs); a one-off solve traces all m.
//!
//! Tracing, the reconstruction and exact single scattering go through a `PhotonBackend`
//! (backend.rs): the CPU's code, or the GPU's kernels in volscatter-gpu; the modules they need
//! (cache, fixed, ring, trace, upsample) are public for it.
//!
//! Upsampling (reconstruct.rs): mass-weighted trilinear by default, the paper's physically
//! based filter (Sec. 4.3, upsample.rs) by the `upsampling` setting; settings.rs has the
//! measurements behind the default.

pub mod backend;
pub mod cache;
pub mod fixed;
mod reconstruct;
pub mod ring;
pub mod settings;
pub mod trace;
pub mod upsample;

#[cfg(test)]
mod physics_tests;
#[cfg(test)]
mod temporal_tests;
#[cfg(test)]
mod tests;

pub use reconstruct::Lobe;
pub use settings::{Angular, PhotonGridSettings, Similarity, SingleScattering, Upsampling};
pub use trace::EnergyReport;

use crate::stages::single_scattering::DOME_DIRECTIONS;
use crate::stages::single_scattering::{dome_directions_for, single_scattering_kept, SingleCache};
use crate::error::{Error, Result};
use crate::medium::MajorantGrid;
use crate::scene::Scene;
use crate::solvers::session::SessionState;
use crate::solvers::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Counters, Progress, Timings};
use backend::{CpuBackend, PhotonBackend, TraceJob};
use ring::{Generation, KeptRing, Ring};
use crate::translate::LightSampler;

/// Light scattered fewer times than this goes into a cell's first lobe, the rest into its
/// second: two HG lobes per cell instead of the paper's one, because the inward, once-scattered
/// sun lobe and the outward diffuse flux cancel in one moment vector (measured:
/// docs/solvers/photon-grid.md). Order 2 is the natural cut: once scattered light is the
/// medium's HG(g) about the sun, what follows is the diffuse part.
const SPLIT_ORDER: u32 = 2;

#[derive(Clone)]
pub struct PhotonGrid {
    settings: PhotonGridSettings,
    /// The first photon generation a one-off solve traces (`from_generation`).
    first: u64,
}

/// What a solve measured besides S.
#[derive(Clone, Debug, Default)]
pub struct PhotonGridReport {
    /// Where the cache's photons' energy went (all its generations).
    pub energy: EnergyReport,
    /// The generations the cache holds (ring.rs), oldest first.
    pub generations: Vec<u64>,
}

impl PhotonGrid {
    pub fn new(settings: PhotonGridSettings) -> Result<Self> {
        settings.validate()?;
        Ok(PhotonGrid { settings, first: 0 })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        PhotonGrid::new(parse_settings(map)?)
    }

    /// Traces `generations` (ring.rs) of `scene` into caches on the frame it returns, on
    /// `backend`.
    fn trace(&self, scene: &Scene, generations: &[u64], timings: &mut Timings, progress: &dyn Progress, backend: &dyn PhotonBackend) -> Result<(cache::Cache, Vec<Generation>)> {
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
            progress,
            view_from: (s.angular == Angular::Camera).then_some(scene.camera.position),
        };
        let job = TraceJob { tracer: &tracer, sampler: &sampler, empty: &empty };
        // Camera weights exist in trace.rs only (settings.rs `needs_cpu`): such a solve traces
        // on the CPU whatever backend it was given, rather than get the lobes from a GPU.
        let backend: &dyn PhotonBackend = if self.settings.needs_cpu().is_some() { &CpuBackend } else { backend };
        let generations = timings.time("trace", || backend.trace_generations(&job, generations))?;
        // Cut-short generations must not reach a session's ring.
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        Ok((empty, generations))
    }

    /// The ring of generations first..first + m, traced afresh: the one-off solve when
    /// `first` is 0.
    fn fresh_ring(&self, scene: &Scene, first: u64, timings: &mut Timings, progress: &dyn Progress, backend: &dyn PhotonBackend) -> Result<Ring> {
        let gens: Vec<u64> = (first..first + self.settings.generations as u64).collect();
        let (cache, traced) = self.trace(scene, &gens, timings, progress, backend)?;
        Ok(Ring::new(&self.settings, cache, traced))
    }

    /// S from the ring's cache: its lobes towards the camera, plus exact single scattering.
    /// `kept`: the session's single-scattering parts, used on the CPU (None on a device);
    /// `lobes`: the ring's tallies as lobes when already made from it (else made and put there);
    /// `mass`: a session's kept cell masses and the frame's medium key (None in a one-off solve).
    #[allow(clippy::too_many_arguments)]
    fn finish(&self, scene: &Scene, ring: &Ring, mut timings: Timings, progress: &dyn Progress, backend: &dyn PhotonBackend, kept: Option<Option<&mut SingleCache>>, lobes: &mut Option<[cache::Tallies; 2]>, mass: Option<(&mut KeptMass, &MediumOf)>, counters: &mut Counters) -> Result<(SolveOutput, PhotonGridReport)> {
        if !progress.update("reconstruct", 0.8) {
            return Err(Error::Cancelled);
        }
        let medium = &scene.medium;
        let lobe = |t, mass| if progress.cancelled() { Err(Error::Cancelled) } else { Ok(cache::Tallies::with_mass(ring.cache(), t, mass)) };
        let [first, second] = ring.total();
        if lobes.is_some() {
            counters.kept("photon lobes");
        } else {
            let m = timings.time("cell mass", || self.cell_mass(medium, ring.cache(), mass, counters));
            *lobes = Some(timings.time("cache", || Ok::<_, Error>([lobe(first, m.clone())?, lobe(second, m)?]))?);
        }
        let Some(tallies) = lobes.as_ref() else { unreachable!("the lobes were set just above") };
        let res = self.settings.output_dim(medium);
        // The backend sizes its grid from `output_resolution`: give it the voxel-aligned one.
        let out = PhotonGridSettings { output_resolution: res, ..self.settings.clone() };
        let mut s = timings.time("reconstruct", || backend.reconstruct(medium, tallies, scene.camera.position, &out, progress))?;
        if self.settings.single_scattering == SingleScattering::Exact {
            let dirs = dome_directions_for(scene, DOME_DIRECTIONS);
            let single = timings.time("single scattering", || match kept {
                Some(cache) => single_scattering_kept(scene, res, dirs, 1, progress, cache, counters),
                None => backend.single_scattering(scene, res, dirs, progress),
            })?;
            // Same medium, same max_dim (`output_dim`): the same frame. Checked, not assumed: a
            // backend that sized its grid from `output_resolution` alone would pair the wrong points.
            if single.dims != s.dims {
                return Err(Error::InvalidArgument(format!("photon-grid: single scattering on {:?} points, the reconstruction on {:?}", single.dims, s.dims)));
            }
            for (a, b) in s.data.iter_mut().zip(&single.data) {
                *a += *b;
            }
        }
        progress.update("done", 1.0);
        Ok((SolveOutput::new(crate::lattice_product::finished(medium, s), timings), PhotonGridReport { energy: ring.energy(), generations: ring.generations() }))
    }

    /// This solver with one-off solves tracing generations first..first + m: what a session's
    /// ring holds m frames after the scene last changed (0, the default: the first frame's).
    pub fn from_generation(&self, first: u64) -> Self {
        PhotonGrid { first, settings: self.settings.clone() }
    }

    #[allow(clippy::too_many_arguments)]
    fn solve_generations(&self, scene: &Scene, first: u64, progress: &dyn Progress, backend: &dyn PhotonBackend, kept: Option<Option<&mut SingleCache>>, counters: &mut Counters) -> Result<(SolveOutput, PhotonGridReport)> {
        let mut timings = Timings::default();
        if !progress.update("photons", 0.0) {
            return Err(Error::Cancelled);
        }
        let ring = self.fresh_ring(scene, first, &mut timings, progress, backend)?;
        self.finish(scene, &ring, timings, progress, backend, kept, &mut None, None, counters)
    }

    /// One frame of a session: the first frame (or one after the settings changed) fills the
    /// ring, each later one traces a single new generation into it (ring.rs). With one
    /// generation, the one-off solve.
    fn solve_in_session(&self, scene: &Scene, progress: &dyn Progress, state: &mut SessionState, backend: &dyn PhotonBackend, on_cpu: bool, counters: &mut Counters) -> Result<(SolveOutput, PhotonGridReport)> {
        if self.settings.generations == 1 {
            return self.solve_keeping_photons(scene, progress, state, backend, on_cpu, counters);
        }
        // The ring's frames keep no single scattering (their S is not the one-off's anyway).
        let single = on_cpu.then_some(None);
        let mut timings = Timings::default();
        if !progress.update("photons", 0.0) {
            return Err(Error::Cancelled);
        }
        let kept = state.kept(KeptRing::default);
        match kept.0.as_mut().filter(|r| r.traced_with(&self.settings)) {
            Some(ring) => {
                let next = ring.next_generation();
                let (cache, mut traced) = self.trace(scene, &[next], &mut timings, progress, backend)?;
                ring.move_to(&cache);
                if let Some(g) = traced.pop() {
                    ring.replace(g);
                }
            }
            None => kept.0 = Some(self.fresh_ring(scene, 0, &mut timings, progress, backend)?),
        }
        match kept.0.as_ref() {
            Some(ring) => self.finish(scene, ring, timings, progress, backend, single, &mut None, None, counters),
            None => unreachable!("the ring was set just above"),
        }
    }

    /// A session frame of one generation: the photons traced for the last frame are kept while
    /// the medium and the lights stay (a camera move: they do not depend on the camera, but
    /// with `angular = camera`), so the frame only reconstructs S towards the new camera.
    fn solve_keeping_photons(&self, scene: &Scene, progress: &dyn Progress, state: &mut SessionState, backend: &dyn PhotonBackend, on_cpu: bool, counters: &mut Counters) -> Result<(SolveOutput, PhotonGridReport)> {
        // The medium's key, hashed once a frame: the photons' key and the cell masses' both hold it.
        let medium = crate::stages::diff::medium_key(&scene.medium);
        let key = (self.settings.angular != Angular::Camera).then(|| traced_key(scene, &medium));
        let kept = state.kept(KeptPhotons::default).0.take().filter(|(k, r, _)| Some(k) == key.as_ref() && r.traced_with(&self.settings));
        let mut timings = Timings::default();
        if !progress.update("photons", 0.0) {
            return Err(Error::Cancelled);
        }
        let (ring, mut lobes) = match kept {
            Some((_, ring, lobes)) => {
                counters.kept("photons");
                (ring, lobes)
            }
            None => {
                counters.computed("photons");
                (self.fresh_ring(scene, self.first, &mut timings, progress, backend)?, None)
            }
        };
        let mut mass = std::mem::take(&mut state.kept(KeptPhotons::default).1);
        let single = on_cpu.then(|| Some(state.single()));
        let out = self.finish(scene, &ring, timings, progress, backend, single, &mut lobes, Some((&mut mass, &medium)), counters)?;
        let kept = state.kept(KeptPhotons::default);
        kept.1 = mass;
        if let Some(k) = key {
            kept.0 = Some((k, ring, lobes));
        }
        Ok(out)
    }

    /// The view-independent first lobe (fluence, g', direction) at world points (light
    /// scattered less than `SPLIT_ORDER` times; in `exact` mode without the unscattered light):
    /// the cache as a host could keep it to re-light from any view.
    pub fn lobes(&self, scene: &Scene, points: &[glam::Vec3]) -> Result<Vec<Lobe>> {
        if self.settings.angular == Angular::Camera {
            return Err(Error::InvalidArgument("photon-grid: angular = camera keeps S towards the camera, not the view-independent lobes".into()));
        }
        let ring = self.fresh_ring(scene, 0, &mut Timings::default(), &crate::stages::NoProgress, &CpuBackend)?;
        let first = cache::Tallies::from_fixed(&scene.medium, ring.cache(), &ring.total()[0]);
        Ok(points.iter().map(|&p| reconstruct::lobe_at(&scene.medium, &first, p, self.settings.upsampling)).collect())
    }
}

/// A medium's key (`diff::medium_key`): its density grid and parameters, and its emission.
type MediumOf = (crate::medium::key::MediumKey, u64);

/// What the photons of a frame depend on besides the settings: the medium and the lights.
type TracedKey = (MediumOf, Vec<u64>);

fn traced_key(scene: &Scene, medium: &MediumOf) -> TracedKey {
    (medium.clone(), scene.lights.iter().map(crate::stages::diff::light_key).collect())
}

/// What a one-generation session keeps: the last frame's photons under their key, and their
/// lobes (view-independent too) once made; and the cache cells' masses, which a light move
/// leaves as they are.
#[derive(Default)]
struct KeptPhotons(Option<(TracedKey, Ring, Option<[cache::Tallies; 2]>)>, KeptMass);

/// The density integral over each cache cell (`cache::cell_mass`) under what decides it: the
/// medium and the cache's resolution (its frame is the medium's box at that resolution). At
/// 128^3 it is most of what a light move costs besides the photons.
#[derive(Default)]
struct KeptMass(Option<(MassKey, Vec<f32>)>);

/// The medium's key and the cache's resolution.
type MassKey = (MediumOf, u32);

impl PhotonGrid {
    /// The cache cells' masses: `kept`'s when made for this medium (its key `of`) and
    /// resolution, else made (and kept there).
    fn cell_mass(&self, medium: &crate::medium::Medium, cache: &cache::Cache, kept: Option<(&mut KeptMass, &MediumOf)>, counters: &mut Counters) -> Vec<f32> {
        let Some((kept, of)) = kept else {
            return cache::cell_mass(medium, &cache.frame);
        };
        let key = (of.clone(), self.settings.cache_resolution);
        if let Some((k, mass)) = &kept.0 {
            if *k == key {
                counters.kept("photon cell mass");
                return mass.clone();
            }
        }
        counters.computed("photon cell mass");
        let mass = cache::cell_mass(medium, &cache.frame);
        kept.0 = Some((key, mass.clone()));
        mass
    }
}

impl Solver for PhotonGrid {
    fn name(&self) -> &'static str {
        "photon-grid"
    }
    /// Camera-weighted photons (`angular = camera`) depend on the camera at any g.
    fn view_independent(&self, scene: &Scene) -> bool {
        scene.medium.g == 0.0 && self.settings.angular != Angular::Camera
    }

    /// The ring (generations > 1) averages the last frames' photons: a repeated scene traces
    /// another generation.
    fn repeatable(&self) -> bool {
        self.settings.generations == 1
    }

    /// S with the energy report (`PhotonGridReport`) attached; the tracing on the device's
    /// `PhotonBackend` when the context carries one; in a session, the ring of partial caches.
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let backend: &dyn PhotonBackend = ctx.backend::<dyn PhotonBackend>().unwrap_or(&CpuBackend);
        let progress = ctx.progress();
        let on_cpu = !ctx.on_device();
        let mut counters = Counters::default();
        let (out, report) = match ctx.session() {
            Some(state) => self.solve_in_session(scene, progress, state, backend, on_cpu, &mut counters)?,
            None => self.solve_generations(scene, self.first, progress, backend, on_cpu.then_some(None), &mut counters)?,
        };
        Ok(out.with_counters(counters).with_report(report))
    }
}
