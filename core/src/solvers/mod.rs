//! The shared solver interface (DESIGN.md "What a solver returns"): every solver turns a
//! `Scene` into a scattering grid S(x) = sigma_s(x) * integral p(w_view, w') L(x, w') dw' —
//! in-scattered radiance per metre towards the camera, RGB, on a grid over the medium.

pub mod limits;
pub mod lpm;
pub mod network;
pub mod photon_grid;
pub mod pop;
pub mod reference;
pub mod registry;
pub mod session;
pub mod settings_table;
pub mod vpl;
/// The shared test harness (fixture scenes and their reference solutions, the metrics, the
/// ratchet check): compiled for this crate's tests and, with the `testing` feature, for other
/// crates' tests and benchmark examples (never in a plain build).
#[cfg(any(test, feature = "testing"))]
pub mod testing;
#[cfg(test)]
mod many_lights_tests;

use std::any::Any;

use crate::error::{Error, Result};
use crate::image::Image;
use crate::scene::Scene;
use crate::stages::{Counters, Progress, ScatteringGrid, Timings};
use session::SessionState;

/// What a solver returns: the scattering grid, the time each stage took, and what the solver
/// measured along the way (its own report type, read back with `report`).
pub struct SolveOutput {
    pub scattering: ScatteringGrid,
    pub timings: Timings,
    /// What the host should tell the user (a light left out, ...): library code never prints.
    pub notes: Vec<String>,
    /// What the solve computed and what it kept from earlier frames of its session, and on a
    /// device what it created, uploaded, read back and submitted.
    pub counters: Counters,
    report: Option<Box<dyn Any + Send + Sync>>,
}

impl SolveOutput {
    pub fn new(scattering: ScatteringGrid, timings: Timings) -> Self {
        SolveOutput { scattering, timings, notes: Vec::new(), counters: Counters::default(), report: None }
    }

    /// This output with `counters` (the solve's own).
    pub fn with_counters(mut self, counters: Counters) -> Self {
        self.counters = counters;
        self
    }

    /// This output with the solver's report attached (PopReport, VplReport, ...).
    pub fn with_report<R: Any + Send + Sync>(mut self, report: R) -> Self {
        self.report = Some(Box::new(report));
        self
    }

    /// The solver's report, if it is of type `R`.
    pub fn report<R: Any>(&self) -> Option<&R> {
        self.report.as_ref().and_then(|r| r.downcast_ref::<R>())
    }

    /// The output and its report of type `R` (the report's `Default` if it has another type).
    pub fn split<R: Any + Default>(mut self) -> (Self, R) {
        let report = self.report.take().and_then(|r| (r as Box<dyn Any>).downcast::<R>().ok()).map(|r| *r).unwrap_or_default();
        (self, report)
    }
}

/// What a solve runs with besides the scene: progress and cancelling, the session's kept state
/// (or none: a one-off solve), and the backend of the device it runs on (none: the CPU). One
/// context serves every way of solving, so each solver has one entry, `Solver::solve`.
pub struct SolveCtx<'a> {
    progress: &'a dyn Progress,
    state: Option<&'a mut SessionState>,
    backend: Option<&'a dyn Any>,
}

impl<'a> SolveCtx<'a> {
    /// A one-off solve on the CPU.
    pub fn new(progress: &'a dyn Progress) -> Self {
        SolveCtx { progress, state: None, backend: None }
    }

    /// One frame of a session: the solver may keep what it can reuse in `state`.
    pub fn in_session(mut self, state: &'a mut SessionState) -> Self {
        self.state = Some(state);
        self
    }

    /// On a device: `backend` is that device's entry for the solver (volscatter-gpu's table
    /// holds a `Box<dyn TheSolversBackendTrait>` for each solver that has one).
    pub fn on(mut self, backend: &'a dyn Any) -> Self {
        self.backend = Some(backend);
        self
    }

    pub fn progress(&self) -> &'a dyn Progress {
        self.progress
    }

    /// The session's state, None for a one-off solve.
    pub fn session(&mut self) -> Option<&mut SessionState> {
        self.state.as_deref_mut()
    }

    /// The single-scattering grid of `scene` (stages/single_scattering.rs), in a session from
    /// the parts kept from the last frame where their inputs did not change; what it computed
    /// and kept goes to `counters`.
    pub fn single_scattering(&mut self, scene: &Scene, size: impl Into<crate::stages::grid::GridSize>, dome_directions: u32, dome_spacing: u32, counters: &mut Counters) -> Result<ScatteringGrid> {
        let progress = self.progress;
        let cache = self.session().map(|s| s.single());
        crate::stages::single_scattering::single_scattering_kept(scene, size, dome_directions, dome_spacing, progress, cache, counters)
    }

    /// Whether this solve runs on a device's backend (else on the CPU).
    pub fn on_device(&self) -> bool {
        self.backend.is_some()
    }

    /// The device's backend of trait `B` (`dyn PopBackend`, ...), None on the CPU.
    pub fn backend<B: ?Sized + 'static>(&self) -> Option<&'a B> {
        let any: &'a dyn Any = self.backend?;
        any.downcast_ref::<Box<B>>().map(|b| b.as_ref())
    }
}

pub trait Solver: Send + Sync {
    fn name(&self) -> &'static str;

    /// The scattering grid of `scene`. In a session (`ctx.session()`), the solver may reuse
    /// what it kept from earlier frames and keep more, but returns exactly what a one-off solve
    /// would for this scene unless its documentation says otherwise (session.rs).
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput>;

    /// Whether this solver's S for `scene` is the same wherever the camera is: then a session
    /// whose scene changed only in its camera hands back the last frame's S (pipeline/session.rs).
    /// The camera enters S through the phase function towards it, a constant in an isotropic
    /// medium (g = 0); a solver whose S depends on the camera otherwise says so
    /// (`view_independent_solvers_give_the_same_s_from_any_camera` checks every claim).
    fn view_independent(&self, scene: &Scene) -> bool {
        scene.medium.g == 0.0
    }

    /// Whether a session's frame of an unchanged scene is the last frame's S (a solver whose
    /// frames average over time, photon-grid's ring, says no).
    fn repeatable(&self) -> bool {
        true
    }

    /// The camera's image rendered directly (RGBA and the AOVs `single`, `multiple`,
    /// `background`), for a solver that renders images rather than scattering grids to
    /// composite (the path tracer); None for the others. `transparent`: the environment seen
    /// directly is left out (alpha from the medium only).
    fn render_image(&self, scene: &Scene, ctx: &mut SolveCtx, transparent: bool, timings: &mut Timings) -> Option<Result<Image>> {
        let _ = (scene, ctx, transparent, timings);
        None
    }
}

/// Parses a solver's settings struct from the `solver` block, ignoring `name` and naming the
/// offending key in errors.
pub fn parse_settings<T: serde::de::DeserializeOwned>(settings: &serde_json::Map<String, serde_json::Value>) -> Result<T> {
    let mut map = settings.clone();
    map.remove("name");
    serde_path_to_error::deserialize(serde_json::Value::Object(map))
        .map_err(|e| Error::scene(format!("solver.{}", e.path()), e.into_inner().to_string()))
}
