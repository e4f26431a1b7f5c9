//! Solving on the device the host chose: the shared entry point of the CLI and the C ABI.
//! Solvers with GPU stages (today: `pop`'s propagation) run them on the GPU; the others, and
//! every solver under `DeviceChoice::Cpu`, run on the CPU. Under `Auto`, a GPU failure (no
//! adapter, out of memory, lost device) falls back to the CPU with a note on stderr.

use crate::device::{DeviceChoice, DeviceUsed};
use crate::{pop, GpuContext, GpuError};
use volscatter_core::solvers::pop::radial::RadialPropagateFn;
use volscatter_core::solvers::pop::{Pop, PropagateFn};
use volscatter_core::solvers::{self, Progress, SolveOutput};
use volscatter_core::{Error, Result, Scene};

/// Residual checks of the GPU propagation happen every this many iterations (one readback).
const CHECK_EVERY: u32 = 8;

fn gpu_error(e: GpuError) -> Error {
    Error::InvalidArgument(format!("GPU: {e}"))
}

/// `pop` with its propagation on the GPU. Options the GPU port does not implement
/// (`vacuum_escape`) run that light on the CPU.
fn pop_on_gpu(ctx: &GpuContext, pop_solver: &Pop, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
    // Local lights' radial grids (pop/radial.rs).
    let radial: &RadialPropagateFn = &|prop, init, j, progress| {
        let (stats, _times) = pop::radial::propagate_radial(ctx, prop, init, j, CHECK_EVERY).map_err(gpu_error)?;
        if !progress.update("pop radial propagation", 1.0) {
            return Err(Error::Cancelled);
        }
        Ok(stats)
    };
    let propagate: &PropagateFn = &|prop, opts, init, a, j, progress| {
        if opts.vacuum_escape {
            return prop.run_with(opts, init, a, j, progress);
        }
        let (stats, _times) = pop::propagate(ctx, prop, init, a, j, CHECK_EVERY).map_err(gpu_error)?;
        if !progress.update("pop propagation", 1.0) {
            return Err(Error::Cancelled);
        }
        Ok(stats)
    };
    let (out, _report) = pop_solver.solve_with_backends(scene, progress, propagate, radial)?;
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
    let cpu = || solvers::by_name(name, settings)?.solve(scene, progress);
    if name != "pop" || choice == DeviceChoice::Cpu {
        return Ok((cpu()?, DeviceUsed::Cpu));
    }
    let pop_solver = Pop::from_settings(settings)?;
    let attempt = GpuContext::new().map_err(gpu_error).and_then(|ctx| {
        let name = ctx.describe();
        pop_on_gpu(&ctx, &pop_solver, scene, progress).map(|out| (out, DeviceUsed::Gpu(name)))
    });
    match attempt {
        Ok(r) => Ok(r),
        Err(Error::Cancelled) => Err(Error::Cancelled),
        Err(e) if choice == DeviceChoice::Auto => {
            eprintln!("note: solving on the CPU ({e})");
            Ok((cpu()?, DeviceUsed::Cpu))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
#[path = "solve_tests.rs"]
mod tests;
