//! `vpl` on the GPU: the backend of `Vpl`'s solve (volscatter-core solvers/vpl/backend.rs). The
//! walks stay on the CPU (as in paper 03); the gather's connections run in `gather.wgsl`, the
//! upsampling in pop's kernel (pop/upsample.rs) and the single scattering in the compositor's
//! (composite/single.rs). What crosses the bus: the VPLs and gather points once, the
//! gather's sums, the merged J (up) and the two output grids (back).

pub mod gather;

use std::sync::Arc;
use crate::context::GpuContext;
use crate::pop::merge::GpuMerged;
use crate::pop::mip::GpuMip;
use volscatter_core::medium::Medium;
use volscatter_core::stages::upsample::Merged;
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::stages::upsample::Upsampling;
use volscatter_core::solvers::vpl::walks::Walks;
use volscatter_core::solvers::vpl::gather::Gathered;
use volscatter_core::solvers::vpl::{VplBackend, VplSettings};
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::{Error, Result, Scene};

pub struct GpuBackend {
    ctx: Arc<GpuContext>,
}

impl GpuBackend {
    pub fn new(ctx: &Arc<GpuContext>) -> Self {
        GpuBackend { ctx: ctx.clone() }
    }
}

impl VplBackend for GpuBackend {
    fn gather(&self, scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<Gathered> {
        gather::gather(&self.ctx, scene, mip, walks, s, progress)
    }

    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &Upsampling) -> Result<ScatteringGrid> {
        let gmip = GpuMip::upload(&self.ctx, mip)?;
        let gmerged = GpuMerged::upload(&self.ctx, merged)?;
        Ok(crate::pop::upsample::upsample(&self.ctx, &gmip, medium, mip, &gmerged, settings)?)
    }

    fn single_scattering(&self, scene: &Scene, s: &VplSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
        // One dispatch: cancellation is looked at before it.
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        Ok(crate::composite::single::single_scattering_grid(&self.ctx, scene, s.output_resolution, s.dome_directions)?)
    }
}

#[cfg(test)]
mod tests;
