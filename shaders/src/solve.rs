//! Solving on the device the host chose: the shared entry point of the CLI and the C ABI.
//! Solvers with GPU stages (today: `pop`: sweep, propagation, merge, upsampling) run them on
//! the GPU; the others, and every solver under `DeviceChoice::Cpu`, run on the CPU. Under `Auto`, a GPU failure (no
//! adapter, out of memory, lost device) falls back to the CPU with a note on stderr.

use crate::device::{DeviceChoice, DeviceUsed};
use crate::pop::backend::{gpu_error, GpuBackend};
use crate::{GpuContext, GpuError};
use volscatter_core::solvers::pop::Pop;
use volscatter_core::solvers::pop::reuse::PopReuse;
use volscatter_core::solvers::session::{Session, SessionState};
use volscatter_core::solvers::{self, Progress, SolveOutput};
use volscatter_core::{Error, Result, Scene};

/// Residual checks of the GPU propagation happen every this many iterations (one readback).
const CHECK_EVERY: u32 = 8;

/// `pop` with its sweep, propagation, merge and upsampling on the GPU.
fn pop_on_gpu(ctx: &GpuContext, pop_solver: &Pop, scene: &Scene, progress: &dyn Progress, state: &mut SessionState) -> Result<SolveOutput> {
    let reuse = state.kept(PopReuse::default);
    let (out, _report) = pop_solver.solve_reusing(scene, progress, &GpuBackend::new(ctx, CHECK_EVERY), Some(reuse))?;
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
    let cpu = |state: &mut SessionState| solvers::by_name(name, settings)?.solve_in_session(scene, progress, state);
    if name != "pop" || choice == DeviceChoice::Cpu {
        return Ok((cpu(state)?, DeviceUsed::Cpu));
    }
    let pop_solver = Pop::from_settings(settings)?;
    let attempt = GpuContext::with_shared(|ctx| {
        let name = ctx.describe();
        // A panic inside wgpu must not reach the host (nor poison the shared context).
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pop_on_gpu(ctx, &pop_solver, scene, progress, state)))
            .unwrap_or_else(|_| Err(gpu_error(GpuError::Internal("a GPU kernel panicked".into()))))
            .map(|out| (out, DeviceUsed::Gpu(name)))
    })
    .map_err(gpu_error)
    .and_then(|r| r);
    match attempt {
        Ok(r) => Ok(r),
        Err(Error::Cancelled) => Err(Error::Cancelled),
        Err(e) if choice == DeviceChoice::Auto => {
            eprintln!("note: solving on the CPU ({e})");
            Ok((cpu(state)?, DeviceUsed::Cpu))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
#[path = "solve_tests.rs"]
mod tests;
