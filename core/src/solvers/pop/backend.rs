//! Where POP's per-light and whole-medium stages run. `Pop`'s solve drives the pipeline
//! (ordinates, mip, light grids, reports) and hands the stages that touch every cell to a
//! `PopBackend`: the CPU code of this module's siblings (`CpuBackend`), or the GPU port in
//! volscatter-gpu, which keeps each light's data in device memory from the sweep through merge
//! and upsampling (hence the associated types: a backend decides where a light's state lives).

use std::any::Any;

use glam::Vec3;

use super::light_grid::LightGrid;
use crate::stages::upsample::Merged;
use crate::stages::mip::MediumMip;
use super::propagate::{Propagation, PropagationStats, RunOptions};
use super::settings::PopSettings;
use super::radial::{self, init::RadialInitial, propagate::RadialPropagation, RadialLight};
use super::{accumulate, init, merge};
use crate::stages::upsample;
use crate::error::Result;
use crate::medium::Medium;
use crate::stages::{Progress, ScatteringGrid};

/// The sums of a transmittance sweep that the energy report needs (see `init::Initial`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SweepSums {
    pub entering: Vec3,
    pub transmitted: Vec3,
    pub absorbed: Vec3,
}

pub trait PopBackend: Sync {
    /// One light between its sweep and the merge: the packets still to propagate and the
    /// accumulation grid J.
    type Light;
    /// All lights merged into the medium-aligned grid, with its density guide.
    type Merged;

    /// Transmittance sweep (init.rs) and single scattering of the unscattered light into a
    /// fresh J (accumulate::add_direct with anisotropy `a0 g`).
    fn init(&self, grid: &LightGrid, fluence: Vec3, mu: &[f32], a0: f32, g: f32, progress: &dyn Progress) -> Result<(Self::Light, SweepSums)>;

    /// A light whose packets are given (the isotropic residuum's, gathered from other grids)
    /// with an empty J.
    fn with_packets(&self, grid: &LightGrid, packets: Vec<Vec3>, mu: &[f32]) -> Result<Self::Light>;

    /// Propagation of the light's packets (propagate.rs), adding into its J.
    fn propagate(&self, light: &mut Self::Light, prop: &Propagation, opts: RunOptions, a_scattered: f32, progress: &dyn Progress) -> Result<PropagationStats>;

    /// A radial grid's propagation (radial/propagate.rs) for local lights; the GPU overrides it.
    fn propagate_radial(&self, prop: &RadialPropagation, init: &RadialInitial, j: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
        radial::cpu_propagate(prop, init, j, progress)
    }

    /// merge.rs over all lights, in order.
    fn merge(&self, medium: &Medium, mip: &MediumMip, lights: &[(LightGrid, Self::Light)], resolution: u32) -> Result<Self::Merged>;

    /// The merged grid's dims and frame.
    fn merged_grid<'m>(&self, merged: &'m Self::Merged) -> &'m ScatteringGrid;

    /// Adds the local lights' radial grids into the merged J (radial::add_to_merged).
    fn add_radial(&self, merged: &mut Self::Merged, lights: &[RadialLight]) -> Result<()>;

    /// upsample.rs: the scattering grid S.
    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &Self::Merged, settings: &PopSettings) -> Result<ScatteringGrid>;

    /// A copy of a propagated light that a later solve of a session may reuse (reuse.rs), or
    /// `None`: the default keeps nothing (the GPU's lights live in device memory).
    fn keep_light(&self, _light: &Self::Light) -> Option<Box<dyn Any + Send>> {
        None
    }

    /// A light kept by `keep_light`, as this backend's light again.
    fn reuse_light(&self, _kept: &(dyn Any + Send)) -> Option<Self::Light> {
        None
    }
}

/// The CPU pipeline.
pub struct CpuBackend;

/// A light on the CPU: its sweep (packets) and accumulation.
#[derive(Clone)]
pub struct CpuLight {
    pub initial: init::Initial,
    pub j: Vec<Vec3>,
}

impl PopBackend for CpuBackend {
    type Light = CpuLight;
    type Merged = Merged;

    fn init(&self, grid: &LightGrid, fluence: Vec3, mu: &[f32], a0: f32, g: f32, progress: &dyn Progress) -> Result<(CpuLight, SweepSums)> {
        let initial = init::sweep_or_cancel(grid, fluence, progress)?;
        let mut j = vec![Vec3::ZERO; grid.len()];
        accumulate::add_direct(&initial.direct, mu, a0, g, &mut j);
        let sums = SweepSums { entering: initial.entering, transmitted: initial.transmitted, absorbed: initial.absorbed };
        Ok((CpuLight { initial, j }, sums))
    }

    fn with_packets(&self, grid: &LightGrid, packets: Vec<Vec3>, _mu: &[f32]) -> Result<CpuLight> {
        let zero = vec![Vec3::ZERO; grid.len()];
        let initial = init::Initial { direct: zero.clone(), packets, entering: Vec3::ZERO, transmitted: Vec3::ZERO, absorbed: Vec3::ZERO };
        Ok(CpuLight { initial, j: zero })
    }

    fn propagate(&self, light: &mut CpuLight, prop: &Propagation, opts: RunOptions, a_scattered: f32, progress: &dyn Progress) -> Result<PropagationStats> {
        prop.run_with(opts, &light.initial, a_scattered, &mut light.j, progress)
    }

    fn merge(&self, medium: &Medium, mip: &MediumMip, lights: &[(LightGrid, CpuLight)], resolution: u32) -> Result<Merged> {
        let views: Vec<(&LightGrid, &[Vec3])> = lights.iter().map(|(g, l)| (g, l.j.as_slice())).collect();
        merge::merge(medium, mip, &views, resolution)
    }

    fn merged_grid<'m>(&self, merged: &'m Merged) -> &'m ScatteringGrid {
        &merged.j
    }

    fn add_radial(&self, merged: &mut Merged, lights: &[RadialLight]) -> Result<()> {
        radial::add_to_merged(&mut merged.j, lights);
        Ok(())
    }

    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &PopSettings) -> Result<ScatteringGrid> {
        upsample::upsample(medium, mip, merged, &settings.upsampling())
    }

    fn keep_light(&self, light: &CpuLight) -> Option<Box<dyn Any + Send>> {
        Some(Box::new(light.clone()))
    }

    fn reuse_light(&self, kept: &(dyn Any + Send)) -> Option<CpuLight> {
        kept.downcast_ref::<CpuLight>().cloned()
    }
}
