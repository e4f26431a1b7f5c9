//! `network` (illumination networks, core solvers/network) on the GPU: the visibility
//! network's binning, sorting and opacities (visibility.rs, with the bitonic sort of sort.rs),
//! the iteration (iterate.rs) and the splat's accumulation (splat.rs). The particles, the phase
//! matrix and the direct light are built on the CPU; the network's lists are read back and
//! kept on the host across a session's frames, as the CPU's are, and this backend uploads what
//! the iteration needs on every call (the GPU buffers are rebuilt per frame: a camera move,
//! which keeps I, uploads nothing to the iteration).

pub mod iterate;
pub mod sort;
pub mod splat;
pub mod visibility;

use std::sync::Arc;
use glam::Vec3;

use crate::GpuContext;
use volscatter_core::solvers::network::backend::{IterationInput, NetworkBackend, SplatInput, VisibilityInput};
use volscatter_core::solvers::network::visibility::DirectionLinks;
use volscatter_core::solvers::network::iterate::Iterated;
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::Result;

/// Iterations recorded between two readbacks of the convergence flag (and looks at
/// cancellation). Iterations after convergence cost a no-op dispatch each, so a larger batch
/// wastes little; 4 keeps a batch under ~50 ms on lavapipe at the default N 2048 x D 64.
pub const CHECK_EVERY: u32 = 4;

pub struct GpuBackend {
    ctx: Arc<GpuContext>,
    check_every: u32,
}

impl GpuBackend {
    pub fn new(ctx: &Arc<GpuContext>, check_every: u32) -> Self {
        GpuBackend { ctx: ctx.clone(), check_every }
    }
}

impl NetworkBackend for GpuBackend {
    fn visibility(&self, input: &VisibilityInput, progress: &dyn Progress) -> Result<Vec<DirectionLinks>> {
        visibility::visibility(&self.ctx, input, progress)
    }

    fn iterate(&self, input: &IterationInput, start: Option<Vec<Vec3>>, progress: &dyn Progress) -> Result<Iterated> {
        Ok(iterate::iterate(&self.ctx, input, start, self.check_every, progress)?)
    }

    fn splat(&self, grid: &mut ScatteringGrid, input: &SplatInput, progress: &dyn Progress) -> Result<()> {
        splat::splat(&self.ctx, grid, input, progress)
    }
}
