//! Solving on the device the host chose: the shared entry point of the CLI and the C ABI.
//! A solver whose registry entry has `gpu` set (today: `pop`: sweep, propagation, merge,
//! upsampling) runs its GPU backend from `gpu_backend`; the others, and every solver under
//! `DeviceChoice::Cpu`, run on the CPU. Under `Auto`, a software adapter or a GPU failure (no
//! adapter, out of memory, lost device: `Error::Device`) runs the CPU solver instead, with a
//! note on stderr.

use crate::device::{try_gpu, Attempt, DeviceChoice, DeviceUsed};
use crate::pop::backend::GpuBackend;
use crate::GpuContext;
use volscatter_core::solvers::pop::Pop;
use volscatter_core::solvers::{self, registry, Progress, SolveOutput};
use volscatter_core::{Error, Result, Scene};

/// Residual checks of the GPU propagation happen every this many iterations (one readback).
const CHECK_EVERY: u32 = 8;

/// A solver's GPU backend: (context, scene, settings, progress) -> its output.
type GpuSolve = fn(&GpuContext, &Scene, &serde_json::Map<String, serde_json::Value>, &dyn Progress) -> Result<SolveOutput>;

/// The GPU backend of solver `name`; every registry entry with `gpu` set has one (tested).
fn gpu_backend(name: &str) -> Option<GpuSolve> {
    match name {
        "pop" => Some(pop_on_gpu),
        _ => None,
    }
}

/// `pop` with its sweep, propagation, merge and upsampling on the GPU.
fn pop_on_gpu(ctx: &GpuContext, scene: &Scene, settings: &serde_json::Map<String, serde_json::Value>, progress: &dyn Progress) -> Result<SolveOutput> {
    let pop_solver = Pop::from_settings(settings)?;
    let (out, _report) = pop_solver.solve_with(scene, progress, &GpuBackend::new(ctx, CHECK_EVERY))?;
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
    let entry = registry::get(name)?;
    let cpu = || solvers::by_name(name, settings)?.solve(scene, progress);
    let backend = match gpu_backend(name) {
        Some(b) if entry.gpu && choice != DeviceChoice::Cpu => b,
        _ => return Ok((cpu()?, DeviceUsed::Cpu)),
    };
    // Settings errors are the same on every device: reported before any adapter is opened.
    (entry.cpu)(settings)?;
    match try_gpu(choice, |ctx| backend(ctx, scene, settings, progress)) {
        Ok(Attempt::Ran(out, used)) => Ok((out, used)),
        Ok(Attempt::Declined(why)) => {
            eprintln!("note: solving on the CPU: {why}");
            Ok((cpu()?, DeviceUsed::Cpu))
        }
        Err(Error::Device(e)) if choice == DeviceChoice::Auto => {
            eprintln!("note: solving on the CPU (device: {e})");
            Ok((cpu()?, DeviceUsed::Cpu))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
#[path = "solve_tests.rs"]
mod tests;
