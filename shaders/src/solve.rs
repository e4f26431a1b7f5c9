//! Solving on the device the host chose: the shared entry point of the CLI and the C ABI.
//! A solver whose registry entry has `gpu` set runs its GPU backend from `gpu_backend` (what
//! each runs on the GPU is said at its function below); the others, and every solver under
//! `DeviceChoice::Cpu`, run on the CPU. Under `Auto`, a software adapter or a GPU failure (no
//! adapter, out of memory, lost device: `Error::Device`) runs the CPU solver instead, with a
//! note on stderr.

use crate::device::{try_gpu, Attempt, DeviceChoice, DeviceUsed};
use crate::lpm::GpuSweeps;
use crate::photon_grid::GpuPhotonBackend;
use crate::pop::backend::GpuBackend;
use crate::GpuContext;
use volscatter_core::solvers::lpm::{Lpm, Overrides};
use volscatter_core::solvers::network::Network;
use volscatter_core::solvers::photon_grid::PhotonGrid;
use volscatter_core::solvers::pop::reuse::PopReuse;
use volscatter_core::solvers::pop::Pop;
use volscatter_core::solvers::session::{Session, SessionState};
use volscatter_core::solvers::{self, auto, registry, SolveOutput};
use volscatter_core::stages::Progress;
use volscatter_core::{Error, Result, Scene};

/// Residual checks of the GPU propagation happen every this many iterations (one readback).
const CHECK_EVERY: u32 = 8;

/// A solver's GPU backend: (context, scene, settings, progress, the session's state) -> its output.
type GpuSolve = fn(&GpuContext, &Scene, &serde_json::Map<String, serde_json::Value>, &dyn Progress, &mut SessionState) -> Result<SolveOutput>;

/// The GPU backend of solver `name`; every registry entry with `gpu` set has one (tested).
fn gpu_backend(name: &str) -> Option<GpuSolve> {
    match name {
        "pop" => Some(pop_on_gpu),
        "photon-grid" => Some(photon_grid_on_gpu),
        "network" => Some(network_on_gpu),
        "lpm" => Some(lpm_on_gpu),
        "vpl" => Some(vpl_on_gpu),
        _ => None,
    }
}

/// `pop` with its sweep, propagation, merge and upsampling on the GPU; what it keeps between
/// the frames of a session (density mip, dome importance) lives in `state`.
fn pop_on_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    state: &mut SessionState,
) -> Result<SolveOutput> {
    let pop_solver = Pop::from_settings(settings)?;
    let reuse = state.kept(PopReuse::default);
    let (out, _report) = pop_solver.solve_reusing(scene, progress, &GpuBackend::new(ctx, CHECK_EVERY), Some(reuse))?;
    Ok(out)
}

/// `photon-grid` with its photon tracing, reconstruction and exact single scattering on the
/// GPU (the rays' drawing, the ring and the cells' mass on the CPU: photon_grid/mod.rs says
/// why); a session's ring lives in `state`.
fn photon_grid_on_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    state: &mut SessionState,
) -> Result<SolveOutput> {
    let solver = PhotonGrid::from_settings(settings)?;
    let (out, _report) = solver.solve_in_session_with(scene, progress, state, &GpuPhotonBackend::new(ctx))?;
    Ok(out)
}

/// `network` with its visibility network (binning, sorting, opacities), its iteration and its
/// splat's accumulation on the GPU; the network and its radiance are kept in `state` on the
/// host, as on the CPU (a camera move re-splats without iterating).
fn network_on_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    state: &mut SessionState,
) -> Result<SolveOutput> {
    let backend = crate::network::GpuBackend::new(ctx, crate::network::CHECK_EVERY);
    let (out, _report) = Network::from_settings(settings)?.solve_on(scene, progress, &backend, Some(state))?;
    Ok(out)
}

/// `lpm` with its sweeps (propagate and collect, every order) on the GPU.
fn lpm_on_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    _state: &mut SessionState,
) -> Result<SolveOutput> {
    let solver = Lpm::from_settings(settings)?;
    Ok(solver.solve_with(scene, progress, Overrides::default(), &GpuSweeps::new(ctx))?.0)
}

/// `vpl` with its gather's connections, upsampling and single scattering on the GPU (the walks
/// and the compensation on the CPU); it keeps nothing between frames.
fn vpl_on_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    _state: &mut SessionState,
) -> Result<SolveOutput> {
    let solver = volscatter_core::solvers::vpl::Vpl::from_settings(settings)?;
    let (out, _report) = solver.solve_with(scene, progress, u32::MAX, &crate::vpl::GpuBackend::new(ctx))?;
    Ok(out)
}

/// Solves `scene` with solver `name` and `settings` on `choice`.
pub fn solve(
    choice: DeviceChoice,
    scene: &Scene,
    name: &str,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
) -> Result<(SolveOutput, DeviceUsed)> {
    solve_in_session(choice, scene, name, settings, progress, &mut SessionState::new())
}

/// One frame of `session` on `choice`: as `solve`, with the session's solver and settings and
/// the state it keeps between frames (volscatter_core::solvers::session).
pub fn solve_session(choice: DeviceChoice, session: &mut Session, scene: &Scene, progress: &dyn Progress) -> Result<(SolveOutput, DeviceUsed)> {
    let (name, settings) = (session.name().to_string(), session.settings().clone());
    let state = session.state_mut();
    state.begin_frame();
    solve_in_session(choice, scene, &name, &settings, progress, state)
}

fn solve_in_session(
    choice: DeviceChoice,
    scene: &Scene,
    name: &str,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    state: &mut SessionState,
) -> Result<(SolveOutput, DeviceUsed)> {
    // Media tracking cannot step and lights beyond float32 are refused on every device, and
    // a non-finite result is an error, never status OK (solvers::guard).
    solvers::guard::check_scene(scene)?;
    // `auto` is resolved here, before the device is picked, so that the solver it picks runs
    // its GPU backend where it has one; the pick goes out with the result.
    let picked = if name == auto::NAME { Some(auto::choose(scene, settings)?) } else { None };
    let (name, settings) = match &picked {
        Some(c) => (c.solver.as_str(), &c.settings),
        None => (name, settings),
    };
    let entry = registry::get(name)?;
    let (mut out, used) = solve_on_device(choice, scene, name, settings, progress, state, entry.gpu)?;
    out.choice = picked;
    solvers::guard::check_finite(scene, "scattering grid", out.scattering.data.iter().copied())?;
    Ok((out, used))
}

/// `solve_in_session` once the scene is checked: the GPU backend when the solver has one
/// (`has_gpu`) and `choice` allows it, else (or on a declined or failed GPU under `Auto`) the CPU.
#[allow(clippy::too_many_arguments)] // the session's pieces, passed through unchanged
fn solve_on_device(
    choice: DeviceChoice,
    scene: &Scene,
    name: &str,
    settings: &serde_json::Map<String, serde_json::Value>,
    progress: &dyn Progress,
    state: &mut SessionState,
    has_gpu: bool,
) -> Result<(SolveOutput, DeviceUsed)> {
    let cpu = |state: &mut SessionState| solvers::by_name(name, settings)?.solve_in_session(scene, progress, state);
    let backend = match gpu_backend(name) {
        Some(b) if has_gpu && choice != DeviceChoice::Cpu => b,
        _ => return Ok((cpu(state)?, DeviceUsed::Cpu)),
    };
    // Settings errors are the same on every device: reported before any adapter is opened.
    (registry::get(name)?.cpu)(settings)?;
    match try_gpu(choice, |ctx| backend(ctx, scene, settings, progress, state)) {
        Ok(Attempt::Ran(out, used)) => Ok((out, used)),
        Ok(Attempt::Declined(why)) => {
            eprintln!("note: solving on the CPU: {why}");
            Ok((cpu(state)?, DeviceUsed::Cpu))
        }
        Err(Error::Device(e)) if choice == DeviceChoice::Auto => {
            eprintln!("note: solving on the CPU (device: {e})");
            Ok((cpu(state)?, DeviceUsed::Cpu))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
#[path = "solve_tests.rs"]
mod tests;
