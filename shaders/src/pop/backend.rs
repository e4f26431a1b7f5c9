//! The backend of `Pop`'s solve on the GPU: every stage that touches every cell runs here, and a
//! light's packets and J stay in device memory from its sweep to the merge, the merged grid from
//! the merge to the upsampling. What crosses the bus: each light grid's coefficients and view
//! cosines (sampled on the CPU) and the density mip, once; back come per-column sums (energy
//! report, stopping test) and the scattering grid S.

use glam::Vec3;
use std::sync::{Arc, Mutex};

use crate::context::{GpuContext, GpuError};
use crate::pop::light::GpuLight;
use crate::pop::merge::GpuMerged;
use crate::pop::mip::GpuMip;
use crate::pop::{init, merge, propagate_resident, upsample, GpuPropagationTimes};
use volscatter_core::medium::Medium;
use volscatter_core::solvers::pop::backend::{PopBackend, SweepSums};
use volscatter_core::solvers::pop::init::Initial;
use volscatter_core::solvers::pop::light_grid::LightGrid;
use volscatter_core::stages::mip::MediumMip;
use volscatter_core::solvers::pop::radial::{self, init::RadialInitial, propagate::RadialPropagation, RadialLight};
use volscatter_core::solvers::pop::propagate::{Propagation, RunOptions};
use volscatter_core::solvers::pop::{PopSettings, PropagationStats};
use volscatter_core::stages::{Progress, ScatteringGrid};
use volscatter_core::{Error, Result};

/// A GPU failure as a solver error (`Error::Device`); `solve` falls back to the CPU on it
/// under `auto`.
pub fn gpu_error(e: GpuError) -> Error {
    e.into()
}

/// One per solve (the GPU table builds one for each solve): it holds that solve's density mip.
pub struct GpuBackend {
    ctx: Arc<GpuContext>,
    /// Residual checks of the propagation every this many iterations (one small readback).
    check_every: u32,
    /// The density mip of this solve, uploaded by the first stage that reads it and dropped by
    /// the last, with the address of the CPU mip it came from as a guard.
    mip: Mutex<Option<(usize, Arc<GpuMip>)>>,
    /// Split of each light's propagation time (benchmarks).
    propagation_times: Mutex<Vec<GpuPropagationTimes>>,
    /// Seconds spent bricking and uploading the mip (part of the merge stage's time).
    mip_upload_s: Mutex<f64>,
}

impl GpuBackend {
    pub fn new(ctx: &Arc<GpuContext>, check_every: u32) -> Self {
        GpuBackend { ctx: ctx.clone(), check_every, mip: Mutex::new(None), propagation_times: Mutex::new(Vec::new()), mip_upload_s: Mutex::new(0.0) }
    }

    /// Upload / iterations / readback times of every propagation so far, in light order.
    pub fn propagation_times(&self) -> Vec<GpuPropagationTimes> {
        self.propagation_times.lock().map(|t| t.clone()).unwrap_or_default()
    }

    /// Seconds spent bricking and uploading the density mip so far.
    pub fn mip_upload_seconds(&self) -> f64 {
        self.mip_upload_s.lock().map(|t| *t).unwrap_or_default()
    }

    fn mip(&self, mip: &MediumMip) -> Result<Arc<GpuMip>> {
        let mut slot = self.mip.lock().map_err(|_| Error::Device("mip lock poisoned".into()))?;
        let key = mip as *const MediumMip as usize;
        if let Some((k, m)) = slot.as_ref() {
            if *k == key {
                return Ok(m.clone());
            }
        }
        let t = std::time::Instant::now();
        let m = GpuMip::resident(&self.ctx, mip).map_err(gpu_error)?;
        if let Ok(mut s) = self.mip_upload_s.lock() {
            *s += t.elapsed().as_secs_f64();
        }
        *slot = Some((key, m.clone()));
        Ok(m)
    }
}

impl PopBackend for GpuBackend {
    type Light = GpuLight;
    type Merged = GpuMerged;

    fn init(&self, grid: &LightGrid, fluence: Vec3, mu: &[f32], a0: f32, g: f32, _progress: &dyn Progress) -> Result<(GpuLight, SweepSums)> {
        self.ctx.idle();
        let mut light = GpuLight::upload(&self.ctx, grid, mu).map_err(gpu_error)?;
        let sums = init::sweep(&self.ctx, &mut light, grid.h, fluence, a0, g).map_err(gpu_error)?;
        Ok((light, sums))
    }

    fn with_packets(&self, grid: &LightGrid, packets: Vec<Vec3>, mu: &[f32]) -> Result<GpuLight> {
        self.ctx.idle();
        let mut light = GpuLight::upload(&self.ctx, grid, mu).map_err(gpu_error)?;
        self.ctx.write(&light.packets, 0, bytemuck::cast_slice(&crate::upload::rgb_as_vec4(&packets)));
        light.injected = packets.iter().copied().sum();
        Ok(light)
    }

    fn propagate(&self, light: &mut GpuLight, prop: &Propagation, opts: RunOptions, a_scattered: f32, progress: &dyn Progress) -> Result<PropagationStats> {
        self.ctx.idle();
        if opts.vacuum_escape || opts.moment_anisotropy {
            return self.propagate_on_cpu(light, prop, opts, a_scattered, progress);
        }
        let (stats, times) = propagate_resident(&self.ctx, light, prop, a_scattered, self.check_every, opts.keep_remaining).map_err(gpu_error)?;
        if let Ok(mut t) = self.propagation_times.lock() {
            t.push(times);
        }
        if !progress.update("pop propagation", 1.0) {
            return Err(Error::Cancelled);
        }
        Ok(stats)
    }

    fn merge(&self, medium: &Medium, mip: &MediumMip, lights: &[(LightGrid, GpuLight)], resolution: u32) -> Result<GpuMerged> {
        self.ctx.idle();
        let gmip = self.mip(mip)?;
        let views: Vec<(&LightGrid, &wgpu::Buffer)> = lights.iter().map(|(g, l)| (g, &*l.j)).collect();
        merge::merge(&self.ctx, &gmip, medium, mip, &views, resolution).map_err(gpu_error)
    }

    fn propagate_radial(&self, prop: &RadialPropagation, init: &RadialInitial, j: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
        self.ctx.idle();
        let (stats, _times) = crate::pop::radial::propagate_radial(&self.ctx, prop, init, j, self.check_every).map_err(gpu_error)?;
        if !progress.update("pop radial propagation", 1.0) {
            return Err(Error::Cancelled);
        }
        Ok(stats)
    }

    fn merged_grid<'m>(&self, merged: &'m GpuMerged) -> &'m ScatteringGrid {
        &merged.grid
    }

    /// The radial grids are sampled on the CPU (radial::add_to_merged), so the merged J makes
    /// one round trip when the scene has local lights.
    fn add_radial(&self, merged: &mut GpuMerged, lights: &[RadialLight]) -> Result<()> {
        self.ctx.idle();
        if lights.is_empty() {
            return Ok(());
        }
        let mut j = merged.grid.clone();
        j.data = crate::pop::light::read_rgb(&self.ctx, &merged.j, merged.grid.dims.iter().map(|&d| d as u64).product()).map_err(gpu_error)?;
        radial::add_to_merged(&mut j, lights);
        self.ctx.write(&merged.j, 0, bytemuck::cast_slice(&crate::upload::rgb_as_vec4(&j.data)));
        Ok(())
    }

    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &GpuMerged, settings: &PopSettings) -> Result<ScatteringGrid> {
        self.ctx.idle();
        let gmip = self.mip(mip)?;
        let out = upsample::upsample(&self.ctx, &gmip, medium, mip, merged, &settings.upsampling()).map_err(gpu_error);
        // The solve's last stage: free the mip (and never serve it to a later solve).
        if let Ok(mut slot) = self.mip.lock() {
            *slot = None;
        }
        out
    }
}

impl GpuBackend {
    /// Options the GPU port lacks (`vacuum_escape`, `moment_anisotropy`): this light's propagation runs on the CPU,
    /// its packets and J crossing the bus both ways.
    fn propagate_on_cpu(&self, light: &mut GpuLight, prop: &Propagation, opts: RunOptions, a_scattered: f32, progress: &dyn Progress) -> Result<PropagationStats> {
        let packets = light.read_packets(&self.ctx).map_err(gpu_error)?;
        let mut j = light.read_j(&self.ctx).map_err(gpu_error)?;
        let initial = Initial { direct: Vec::new(), packets, entering: Vec3::ZERO, transmitted: Vec3::ZERO, absorbed: Vec3::ZERO };
        let stats = prop.run_with(opts, &initial, a_scattered, &mut j, progress)?;
        self.ctx.write(&light.j, 0, bytemuck::cast_slice(&crate::upload::rgb_as_vec4(&j)));
        Ok(stats)
    }
}
