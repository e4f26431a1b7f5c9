//! The GPU as the pipeline's accelerator (core pipeline/device.rs): the table of GPU backends,
//! keyed by registry name, and the composite. What each backend runs on the GPU:
//! - `pop`: the sweep, propagation, merge and upsampling (its kept stages stay in the session);
//! - `photon-grid`: photon tracing, reconstruction and exact single scattering (the rays'
//!   drawing, the ring and the cells' mass on the CPU: photon_grid/mod.rs says why);
//! - `network`: the visibility network (binning, sorting, opacities), the iteration and the
//!   splat's accumulation (the network and its radiance kept on the host in a session);
//! - `lpm`: the sweeps (propagate and collect, every order);
//! - `vpl`: the gather's connections, upsampling and single scattering (the walks and the
//!   compensation on the CPU).

use std::any::Any;
use std::sync::Arc;

use crate::device::{try_gpu, Attempt, DeviceChoice};
use crate::GpuContext;
use volscatter_core::compositor::CompositeOptions;
use volscatter_core::image::Image;
use volscatter_core::pipeline::{Accelerator, Devices};
use volscatter_core::solvers::lpm::stream::SweepBackend;
use volscatter_core::solvers::network::backend::NetworkBackend;
use volscatter_core::solvers::photon_grid::backend::PhotonBackend;
use volscatter_core::solvers::pop::PopDevice;
use volscatter_core::solvers::vpl::backend::VplBackend;
use volscatter_core::solvers::SolveOutput;
use volscatter_core::stages::{Counters, ScatteringGrid};
use volscatter_core::{Result, Scene};

/// Residual checks of the GPU propagation happen every this many iterations (one readback).
const CHECK_EVERY: u32 = 8;

/// Builds a solver's GPU backend as the `Any` its `Solver::solve` downcasts (a boxed trait
/// object of the solver's backend trait).
type MakeBackend = fn(&Arc<GpuContext>) -> Box<dyn Any>;

/// Every GPU backend, by registry name: a solver's registry entry has `gpu` set exactly when it
/// is here (tested).
pub const GPU_BACKENDS: &[(&str, MakeBackend)] = &[
    ("pop", |c| Box::new(Box::new(crate::pop::backend::GpuBackend::new(c, CHECK_EVERY)) as Box<dyn PopDevice>)),
    ("photon-grid", |c| Box::new(Box::new(crate::photon_grid::GpuPhotonBackend::new(c)) as Box<dyn PhotonBackend>)),
    ("network", |c| Box::new(Box::new(crate::network::GpuBackend::new(c, crate::network::CHECK_EVERY)) as Box<dyn NetworkBackend>)),
    ("lpm", |c| Box::new(Box::new(crate::lpm::GpuSweeps::new(c)) as Box<dyn SweepBackend>)),
    ("vpl", |c| Box::new(Box::new(crate::vpl::GpuBackend::new(c)) as Box<dyn VplBackend>)),
];

pub(crate) fn backend_for(name: &str) -> Option<MakeBackend> {
    GPU_BACKENDS.iter().find(|(n, _)| *n == name).map(|(_, make)| *make)
}

/// The process's GPU (its context opened on first use, `GpuContext::with_shared`).
pub struct Gpu;

/// The GPU accelerator every host links in.
pub static GPU: Gpu = Gpu;

/// `choice` among the CPU and the GPU: what the CLI and the C ABI hand the pipeline.
pub fn devices(choice: DeviceChoice) -> Devices {
    Devices::new(choice, &GPU)
}

impl Accelerator for Gpu {
    fn has_backend(&self, name: &str) -> bool {
        backend_for(name).is_some()
    }

    fn solve(&self, choice: DeviceChoice, name: &str, job: &mut dyn FnMut(&dyn Any) -> Result<SolveOutput>) -> Result<Attempt<SolveOutput>> {
        let Some(make) = backend_for(name) else { return Ok(Attempt::Declined(format!("`{name}` has no GPU backend"))) };
        try_gpu(choice, |ctx| {
            // What the device did for this solve: the context's totals across it (one solve
            // at a time holds the shared context).
            let before = ctx.counts();
            ctx.take_stages();
            ctx.idle();
            let mut out = job(make(ctx).as_ref())?;
            let after = ctx.counts();
            out.counters.add(&device_delta(&before, &after));
            // The medium's device objects built or kept (`GpuContext::resident`).
            out.counters.add(&ctx.take_stages());
            ctx.end_solve();
            Ok(out)
        })
    }

    fn single_for(&self, choice: DeviceChoice, scene: &Scene, opts: &CompositeOptions) -> Result<Attempt<Option<ScatteringGrid>>> {
        try_gpu(choice, |ctx| {
            let out = crate::composite::single_for(ctx, scene, opts).map_err(Into::into);
            ctx.end_solve();
            out
        })
    }

    fn composite(&self, choice: DeviceChoice, scene: &Scene, s: &ScatteringGrid, single: Option<&ScatteringGrid>, opts: &CompositeOptions) -> Result<Attempt<Image>> {
        if scene.medium.emission.is_some() {
            return Ok(Attempt::Declined("the GPU compositor does not march the medium's emission yet".into()));
        }
        try_gpu(choice, |ctx| {
            let out = crate::composite::composite_with_single(ctx, scene, s, single, opts).map_err(Into::into);
            ctx.end_solve();
            out
        })
    }
}

/// `after` less `before`, the device's counts only.
fn device_delta(before: &Counters, after: &Counters) -> Counters {
    Counters {
        bytes_uploaded: after.bytes_uploaded - before.bytes_uploaded,
        bytes_read_back: after.bytes_read_back - before.bytes_read_back,
        pipelines_created: after.pipelines_created - before.pipelines_created,
        buffers_created: after.buffers_created - before.buffers_created,
        submissions: after.submissions - before.submissions,
        ..Counters::default()
    }
}

#[cfg(test)]
#[path = "backends_tests.rs"]
mod tests;
