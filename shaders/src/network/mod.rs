//! `network` (illumination networks, core solvers/network) with its iteration on the GPU.
//! The network (particles, visibility lists and opacities, phase matrix) and the direct light
//! are built on the CPU and kept there across a session's frames; this backend uploads what
//! the iteration needs on every call (the GPU buffers are rebuilt per frame: a camera move,
//! which keeps I, uploads nothing to the iteration). The splat's accumulation (points x
//! particles) runs on the GPU too (splat.rs).

pub mod iterate;
pub mod splat;
#[cfg(test)]
mod bench;

use glam::Vec3;

use crate::GpuContext;
use volscatter_core::solvers::network::backend::{IterationInput, NetworkBackend, SplatInput};
use volscatter_core::solvers::network::iterate::Iterated;
use volscatter_core::solvers::{Progress, ScatteringGrid};
use volscatter_core::Result;

/// Iterations recorded between two readbacks of the convergence flag (and looks at
/// cancellation). Iterations after convergence cost a no-op dispatch each, so a larger batch
/// wastes little; 4 keeps a batch under ~50 ms on lavapipe at the default N 2048 x D 64.
pub const CHECK_EVERY: u32 = 4;

pub struct GpuBackend<'c> {
    ctx: &'c GpuContext,
    check_every: u32,
}

impl<'c> GpuBackend<'c> {
    pub fn new(ctx: &'c GpuContext, check_every: u32) -> Self {
        GpuBackend { ctx, check_every }
    }
}

impl NetworkBackend for GpuBackend<'_> {
    fn iterate(&self, input: &IterationInput, start: Option<Vec<Vec3>>, progress: &dyn Progress) -> Result<Iterated> {
        Ok(iterate::iterate(self.ctx, input, start, self.check_every, progress)?)
    }

    fn splat(&self, grid: &mut ScatteringGrid, input: &SplatInput, progress: &dyn Progress) -> Result<()> {
        splat::splat(self.ctx, grid, input, progress)
    }
}
