//! Where `vpl`'s heavy stages run. `Vpl`'s solve traces the walks on the CPU (as the
//! paper does) and hands the stages that touch every gather or output point to a
//! `VplBackend`: the CPU code of this module's siblings (`CpuBackend`), or the GPU port in
//! volscatter-gpu (shaders/src/vpl).

use super::gather::{self, Gathered};
use super::settings::VplSettings;
use super::walks::Walks;
use crate::stages::single_scattering::single_scattering_grid_dome_spaced;
use crate::error::Result;
use crate::medium::Medium;
use crate::scene::Scene;
use crate::stages::upsample::Merged;
use crate::stages::mip::MediumMip;
use crate::stages::upsample::Upsampling;
use crate::stages::upsample;
use crate::stages::{Progress, ScatteringGrid};

pub trait VplBackend: Sync {
    /// gather.rs: J on the gather grid with its density guide, J_iso, and the near field's
    /// report.
    fn gather(&self, scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<Gathered>;

    /// pop's upsample.rs: the multiple scattering S on the output grid.
    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &Upsampling) -> Result<ScatteringGrid>;

    /// The compositor's single-scattering grid on the output frame.
    fn single_scattering(&self, scene: &Scene, s: &VplSettings, progress: &dyn Progress) -> Result<ScatteringGrid>;
}

/// The CPU pipeline.
pub struct CpuBackend;

impl VplBackend for CpuBackend {
    fn gather(&self, scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<Gathered> {
        gather::gather(scene, mip, walks, s, progress)
    }

    fn upsample(&self, medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &Upsampling) -> Result<ScatteringGrid> {
        upsample::upsample(medium, mip, merged, settings)
    }

    fn single_scattering(&self, scene: &Scene, s: &VplSettings, progress: &dyn Progress) -> Result<ScatteringGrid> {
        single_scattering_grid_dome_spaced(scene, s.output_resolution, s.dome_directions, s.dome_spacing, progress)
    }
}
