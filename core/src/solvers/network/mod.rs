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
//! In a session (session.rs) the network is kept while the medium stays, and so is its
//! radiance I[particle, direction] for the last few lights: a camera move, or a return to a
//! light still remembered, re-splats it without iterating; another light iterates from zero as
//! a one-off solve does. Every frame is bit-identical to its one-off solve. (A warm start from
//! the previous I was dropped: it stopped at another point within the residual threshold, up to
//! 2.2e-3 away in S, and a return to an earlier light did not return to its answer.)
//!
//! The stages over every (particle, direction) pair and every output cell (the visibility
//! network's binning, sorting and opacities, the iteration, the splat) run through a
//! `NetworkBackend` (backend.rs): the CPU code here, or volscatter-gpu's port. The particles,
//! the phase matrix and the direct light are built on the CPU.

pub mod backend;
mod direct;
mod directions;
pub mod iterate;
pub mod particles;
pub mod settings;
pub mod splat;
pub mod visibility;
#[cfg(test)]
mod session_tests;
#[cfg(test)]
mod tests;

pub use settings::NetworkSettings;

use crate::lattice_product::finished;
use backend::{CpuBackend, IterationInput, NetworkBackend, SplatInput, VisibilityInput};

use crate::medium::key::MediumKey;
use super::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Counters, Progress, Timings};
use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::translate::sampling::BoundingSphere;

pub struct Network {
    settings: NetworkSettings,
    /// Rows of the phase matrix normalised to sum 1 (directions.rs). Always, but for the test
    /// that shows the white furnace failing without it.
    normalise_phase: bool,
}

/// How a solve came by its network radiance I[particle, direction].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Start {
    /// Iterated from zero (a one-off solve, new lights, or the medium changed).
    #[default]
    Cold,
    /// A kept I: same medium and a bit-identical direct light (this frame's or a remembered
    /// earlier one's), so the iteration would give it again (a camera move only re-splats).
    Kept,
}

/// What a solve measured, for tests and benchmarks.
#[derive(Clone, Debug, Default)]
pub struct NetworkReport {
    pub window: u32,
    /// Residual after each iteration (empty when I was kept).
    pub residuals: Vec<f64>,
    pub start: Start,
}

/// What a session keeps (session.rs): the medium-dependent network and the last answer.
struct Kept {
    medium: MediumKey,
    particles: particles::Particles,
    dirs: Vec<glam::Vec3>,
    links: Vec<visibility::DirectionLinks>,
    phase: Vec<f32>,
    window: u32,
    /// The last few direct lights' first scattering and the I iterated from each, newest
    /// last (at most `REMEMBERED_LIGHTS`).
    answers: Vec<(Vec<glam::Vec3>, Vec<glam::Vec3>)>,
    /// The keys of the lights (and the medium's emission) the newest answer's direct light came
    /// from: while they stay (a camera move), the direct light is not computed again.
    newest_lights: Option<(u64, Vec<u64>)>,
}

/// How many lights' I a session remembers: enough to toggle between a few lights or key
/// frames without iterating, at N x D x 24 bytes each (a 4096 x 128 network: 12 MB).
const REMEMBERED_LIGHTS: usize = 4;

fn same_bits(a: &[glam::Vec3], b: &[glam::Vec3]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits))
}

#[derive(Default)]
struct KeptNetwork(Option<Kept>);

impl Network {
    pub fn new(settings: NetworkSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Network { settings, normalise_phase: true })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Network::new(parse_settings(map)?)
    }

    /// The solve with the network kept in `kept` (a one-off solve passes an empty one): the
    /// network (particles, visibility links, phase matrix) is kept while the medium is the same
    /// (exact key: every voxel's bits, transform and material); I is kept as is when the direct
    /// light is bit-identical to a remembered one (a camera move: S is exactly the one-off
    /// solve's), else iterated from zero.
    /// `scattering` is the single scattering, timed in `timings` and counted in `counters`.
    #[allow(clippy::too_many_arguments)]
    fn solve_keeping(&self, scene: &Scene, progress: &dyn Progress, backend: &dyn NetworkBackend, kept: &mut KeptNetwork, mut scattering: crate::stages::ScatteringGrid, mut timings: Timings, counters: &mut Counters) -> Result<(SolveOutput, NetworkReport)> {
        let s = &self.settings;
        let medium = &scene.medium;
        let mut report = NetworkReport { window: 0, residuals: Vec::new(), start: Start::Cold };
        if medium.grid.is_empty() || medium.albedo.max_element() <= 0.0 {
            // Nothing scatters twice: S is its single scattering.
            return Ok((SolveOutput::new(finished(medium, scattering), timings), report));
        }
        // Radiance, source, first-scattering and visibility arrays: ~4 RGB values per
        // (particle, direction) pair.
        crate::budget::check_elements::<[glam::Vec3; 4]>("network arrays (solver.particles x solver.directions)", s.particles as u64 * s.directions as u64)?;
        let key = timings.time("network medium key", || MediumKey::of(medium));
        let mut net = match kept.0.take().filter(|k| k.medium == key) {
            Some(k) => {
                counters.kept("network visibility");
                k
            }
            None => {
                counters.computed("network visibility");
                let p = timings.time("network particles", || particles::sample(medium, s.particles, s.seed));
                if p.mean_sigma_t <= 0.0 {
                    return Ok((SolveOutput::new(finished(medium, scattering), timings), report));
                }
                let dirs = directions::fibonacci(s.directions);
                let sphere = BoundingSphere::of(medium);
                let window = visibility::window_side(s.window, s.directions, sphere.radius, p.mean_sigma_t, p.len());
                let input = VisibilityInput { medium, particles: &p, dirs: &dirs, centre: sphere.center, radius: sphere.radius, window, opacity: s.opacity };
                let links = timings.time("network visibility", || backend.visibility(&input, progress))?;
                let phase = directions::phase_matrix(&dirs, medium.g, self.normalise_phase);
                Kept { medium: key, particles: p, dirs, links, phase, window, answers: Vec::new(), newest_lights: None }
            }
        };
        report.window = net.window;
        if !progress.update("network visibility", 0.3) {
            return Err(Error::Cancelled);
        }
        // The direct light depends on the particles (kept with the medium), the lights and the
        // medium's emission, not on the camera.
        let lights = (crate::stages::diff::medium_key(medium).1, scene.lights.iter().map(crate::stages::diff::light_key).collect::<Vec<u64>>());
        if net.newest_lights.as_ref() == Some(&lights) && !net.answers.is_empty() {
            counters.kept("network direct");
            counters.kept("network iterate");
            report.start = Start::Kept;
        } else {
            net.newest_lights = None;
            counters.computed("network direct");
            if let Err(e) = self.direct_and_iterate(scene, progress, backend, &mut net, &mut timings, &mut report, counters) {
                // The network itself is whole, and so are the remembered answers.
                kept.0 = Some(net);
                return Err(e);
            }
            net.newest_lights = Some(lights);
        }
        if !progress.update("network iterate", 0.9) {
            kept.0 = Some(net);
            return Err(Error::Cancelled);
        }
        let Some((_, radiance)) = net.answers.last() else { unreachable!("an answer was just found or pushed") };
        let input = SplatInput {
            medium,
            particles: &net.particles,
            radiance,
            dirs: &net.dirs,
            camera: scene.camera.position,
            kernel_radius: s.kernel_radius,
            range_sigma: s.range_sigma,
        };
        let splatted = timings.time("network splat", || backend.splat(&mut scattering, &input, progress));
        // Kept whether or not the splat succeeded: a failed GPU splat leaves a whole network
        // and I for the CPU fallback or the next frame.
        kept.0 = Some(net);
        splatted?;
        progress.update("network splat", 1.0);
        Ok((SolveOutput::new(finished(medium, scattering), timings), report))
    }
}

impl Network {
    /// The direct light's first scattering at the particles, and I iterated from it (or a
    /// remembered answer of a bit-identical direct light), made `net`'s newest answer.
    #[allow(clippy::too_many_arguments)]
    fn direct_and_iterate(&self, scene: &Scene, progress: &dyn Progress, backend: &dyn NetworkBackend, net: &mut Kept, timings: &mut Timings, report: &mut NetworkReport, counters: &mut Counters) -> Result<()> {
        let s = &self.settings;
        let medium = &scene.medium;
        let Some(first) = timings.time("network direct", || direct::first_scattering(scene, &net.particles, &net.dirs, s.dome_directions, progress)) else {
            return Err(Error::Cancelled);
        };
        let remembered = net.answers.iter().position(|(f, _)| same_bits(f, &first));
        if let Some(k) = remembered {
            counters.kept("network iterate");
            report.start = Start::Kept;
            let answer = net.answers.remove(k);
            net.answers.push(answer);
        } else {
            counters.computed("network iterate");
            report.start = Start::Cold;
            let input = IterationInput { links: &net.links, phase: &net.phase, first: &first, albedo: medium.albedo, max_iterations: s.max_iterations, threshold: s.residual_threshold };
            let it = timings.time("network iterate", || backend.iterate(&input, None, progress))?;
            report.residuals = it.residuals;
            if net.answers.len() >= REMEMBERED_LIGHTS {
                net.answers.remove(0);
            }
            net.answers.push((first, it.radiance));
        }
        Ok(())
    }
}

impl Solver for Network {
    fn name(&self) -> &'static str {
        "network"
    }

    /// S with what the iteration did (`NetworkReport`) attached; the iteration and the splat on
    /// the device's `NetworkBackend` when the context carries one. The network and I are kept
    /// on the host in a session, so a camera move costs only the splat.
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let backend: &dyn NetworkBackend = ctx.backend::<dyn NetworkBackend>().unwrap_or(&CpuBackend);
        let progress = ctx.progress();
        let s = &self.settings;
        let mut counters = Counters::default();
        let mut timings = Timings::default();
        let single = timings.time("network single scattering", || ctx.single_scattering(scene, s.output_resolution, s.dome_directions, 1, &mut counters))?;
        let mut one_off = KeptNetwork(None);
        let kept = match ctx.session() {
            Some(state) => state.kept(KeptNetwork::default),
            None => &mut one_off,
        };
        let (out, report) = self.solve_keeping(scene, progress, backend, kept, single, timings, &mut counters)?;
        Ok(out.with_counters(counters).with_report(report))
    }
}
