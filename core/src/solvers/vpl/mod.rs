//! `vpl`: instant multiple scattering with virtual point lights (paper 03).
//!
//! Pipeline: random walks from every light (walks.rs) leave anisotropic VPLs at their
//! scattering vertices; the VPLs are gathered on a coarse grid over the medium, each point
//! connecting to its own interleaved subset of walks with ray-marched transmittance
//! (gather.rs), G clamped at a radius R of one gather cell and the clamped energy restored by
//! the paper's bias compensation (compensate.rs, `near_field: compensate`; the default,
//! `near_field: auto`, is the ball kernel on thin media and the attenuated top hat on dense
//! ones, settings.rs says why); the
//! gathered J (per unit sigma_s) is upsampled to the output grid by pop's density-guided joint
//! bilateral filter (stages/upsample.rs), giving the multiple scattering; the single scattering
//! is added exactly from the compositor's single-scattering grid, on the same output frame.
//!
//! Departures from the paper (and from issue 16):
//! - The compensation's last recursion level takes the VPLs with the project's ball kernel of
//!   radius R (bounded, same integral as 1/d^2) instead of unclamped 1/d^2 (compensate.rs).
//!   `near_field: ball` (the ball kernel alone, radius at most a quarter mean free path) and
//!   `clamp` (no compensation) remain as options; measured in tests.rs.
//! - `near_field: hat` (what `auto` takes on dense media): within the near-field radius a VPL
//!   counts as a density estimate over the ball, with the ball's mean of the homogeneous
//!   kernel e^{-sigma d} / d^2 at the point's extinction and the two lobes' mean over the
//!   ball's directions (HG of g^2); T / d^2 beyond (gather.rs `Kernel::Hat`). Lossless at
//!   any optical thickness of the ball, so the ball stays a gather cell where the ball kernel
//!   must shrink to a quarter mean free path and turn heavy-tailed: the dense cloud 8 seeds
//!   x1.080 +- 0.038 -> x0.998 +- 0.010, image errors 0.25-0.80 -> 0.14-0.23 (32768 walks).
//! - The gather runs on a coarse grid and is upsampled, not per pixel (the project's
//!   scattering-grid interface).
//! - Transmittance to VPLs is ray marched (deterministic) at the gather grid's spacing but at
//!   most half a mean free path of the densest voxel (gather::march_step), on a dense copy of
//!   the density (march.rs: the march is ~90% of a solve; 2.8x faster than the sparse lookups,
//!   same values to float rounding). By default (`transmittance: map`) only the connections
//!   within two gather cells are marched: the farther ones look their optical depth up in a
//!   per-point directional map (depth_map.rs): default scene 16384 walks gather 3.03 -> 0.51 s,
//!   image error 0.0869 both (settings.rs).
//! - `upsample_fit: linear` replaces the bilateral filter's weighted mean by a weighted local
//!   linear fit (upsample.rs): the mean is J at the weights' centroid, which a medium's
//!   surface pulls inwards (cube g 0 8 seeds x1.079 bright; the fit x1.013).
//! - `near_refine` (off by default): the VPLs within a few gather cells of each output point
//!   gathered there instead of upsampled (refine.rs): the coarse gather loses the correlation
//!   between the density and the light of VPLs within a cell (local lights beside the plume
//!   6-8% dark at 12-16 cells); noisier than the coarse near field at a few thousand walks.
//! - `near_upsample: ratio` (off by default): the gather's ball kernel (radius ~ a gather
//!   cell) corrected to the output cell's at each output point, from a density integral times
//!   the near light's level upsampled as a ratio (near_ratio.rs): deterministic; +1-2% flux
//!   everywhere (point light beside the plume x0.934 -> x0.950 at 32768 walks), a third of what
//!   a finer gather gives there, and the cubes brighter, so not the default.
//! - `normalize_energy` (on by default): the multiple scattering scaled so that the power it
//!   scatters equals the walks' (energy.rs): the global share of the coarse gather's bias
//!   (point light beside the plume x0.878 -> x0.926 at 4096 walks).
//! - `phase_cone` (on by default): the ball kernel's two phase functions smoothed over the cone
//!   of a ball of up to a quarter gather cell around the VPL (gather.rs `Kernel::Ball`): the
//!   dense cloud's heavy tail, two g 0.9 lobes times 3 / r^2, gone (8 seeds x1.40 +- 0.83 ->
//!   x0.97 +- 0.07).
//! - The gather, upsampling and single scattering run on a backend (backend.rs): the CPU, or
//!   the GPU (volscatter-gpu, shaders/src/vpl), where the connections to the VPLs (the gather
//!   points' and the compensation vertices') run in WGSL; the walks, the compensation's vertex
//!   sampling and the direct light at its vertices stay on the CPU on both.
//! - A VPL sits at every collision of a walk in the medium, the first included: light from a
//!   source to a point is the single scattering (exact, from the compositor), light from a
//!   walk's first collision to a point is double scattering, and so on. (Counting the light
//!   source as a walk's vertex 0, VPLs start at the walk's second vertex.)
//!
//! Measured (tests.rs, 4096 walks, 12-cell gather), image rel. RMSE with the defaults (ball
//! kernel, `normalize_energy`, `phase_cone`, the depth map): cube g 0 0.069, cube g 0.7 0.148,
//! plume g 0.9 0.327, point / spot / rect light beside it 0.111 / 0.093 / 0.147, dense cloud
//! 0.707 with flux x1.04 (before the last two: 0.076, 0.153, 0.362, 0.166 / 0.145 / 0.192 and
//! 0.75 with x0.66). With compensation (not normalized): cube g 0 0.093, cube g 0.7 0.138,
//! plume 0.311, dense cloud 0.62 (x0.66). White furnace box S / sigma_s 0.991 compensated
//! (clamp alone 0.695 at R = 2 cells).

pub mod backend;
pub mod compensate;
pub mod depth_map;
pub mod energy;
pub mod far_field;
pub mod gather;
pub use crate::medium::dense_march as march;
pub mod near_ratio;
pub mod refine;
pub mod settings;
pub mod upsample;
pub mod walks;


use crate::stages::mip::MediumMip;
use crate::stages::upsample::Merged;
use super::{parse_settings, SolveCtx, SolveOutput, Solver};
use crate::stages::{Counters, ScatteringGrid, Timings};
use crate::error::{Error, Result};
use crate::scene::Scene;
pub use backend::{CpuBackend, VplBackend};
pub use gather::GatherStats;
pub use settings::{NearField, NearUpsample, Transmittance, UpsampleFit, VplSettings};

pub struct Vpl {
    pub settings: VplSettings,
    /// Only the first VPLs of each walk are kept (`with_max_orders`).
    max_orders: u32,
}

/// What a solve did: VPLs left, their power, walks cut, the near field's share.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct VplReport {
    pub walks: u32,
    /// The near field that ran (`auto` resolved).
    pub near_field: NearField,
    pub vpls: usize,
    /// Power scattered by all VPLs (W, RGB).
    pub vpl_power: [f32; 3],
    pub walks_cut: u32,
    pub gather: GatherStats,
    /// `normalize_energy`'s powers and factor (None where it does not apply).
    pub energy: Option<energy::EnergyCheck>,
}

impl Vpl {
    pub fn new(settings: VplSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Vpl { settings, max_orders: u32::MAX })
    }

    pub fn from_settings(map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Vpl::new(parse_settings(map)?)
    }

    /// This solver keeping only the first `max_orders` VPLs of each walk (u32::MAX, the
    /// default: all), so that 1 gives single + double scattering.
    pub fn with_max_orders(&self, max_orders: u32) -> Self {
        Vpl { max_orders, settings: self.settings.clone() }
    }

    fn run(&self, scene: &Scene, ctx: &mut SolveCtx, backend: &dyn VplBackend, counters: &mut Counters) -> Result<(SolveOutput, VplReport)> {
        let progress = ctx.progress();
        let max_orders = self.max_orders;
        let medium = &scene.medium;
        let s = &VplSettings { near_field: self.near_field_for(medium)?, ..self.settings.clone() };
        let mut timings = Timings::default();
        if !progress.update("vpl walks", 0.0) {
            return Err(Error::Cancelled);
        }
        let walks = timings.time("vpl walks", || walks::trace(scene, s, max_orders, progress))?;
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let out_probe = crate::stages::ScatteringGrid::over_medium(medium, s.output_resolution)?;
        let gather_probe = crate::stages::ScatteringGrid::over_medium(medium, s.gather_resolution)?;
        let min_fp = crate::stages::upsample::footprint(medium, &out_probe).min(crate::stages::upsample::footprint(medium, &gather_probe));
        let mip = timings.time("vpl mip", || MediumMip::new(medium, min_fp));
        if !progress.update("vpl gather", 0.0) {
            return Err(Error::Cancelled);
        }
        let gathered = timings.time("vpl gather", || backend.gather(scene, &mip, &walks, s, progress))?;
        let (merged, gstats) = (&gathered.merged, gathered.stats);
        let pop_like = s.upsampling();
        let upsample = |merged: &Merged| match (s.upsample, s.upsample_fit) {
            // The linear fit on the CPU for both backends (vpl/upsample.rs).
            (true, UpsampleFit::Linear) => upsample::upsample_linear(medium, &mip, merged, &pop_like, progress),
            _ => backend.upsample(medium, &mip, merged, &pop_like),
        };
        let ratio = s.upsample && s.near_refine == 0.0 && s.near_upsample == NearUpsample::Ratio;
        let mut scattering = if ratio {
            timings.time("vpl upsample", || near_ratio::upsample(scene, &mip, &walks, merged, s, &pop_like, progress, upsample))?
        } else {
            timings.time("vpl upsample", || upsample(merged))?
        };
        if s.near_refine > 0.0 {
            timings.time("vpl near refine", || refine::refine(scene, &mip, &walks, merged, &mut scattering, s, progress, upsample))?;
        }
        // Not with the compensation (the clamp's loss is restored, not spread) nor the hat
        // (lossless by construction: on the dense cloud, 8 seeds at 32768 walks, x0.998
        // without, x0.960 with: the walks' power is set against J_iso's over the output grid,
        // where the hat's light near the lit surface is counted a few percent high).
        let energy = if s.normalize_energy && !matches!(s.near_field, NearField::Compensate | NearField::Hat) && s.near_refine == 0.0 && !ratio && max_orders == u32::MAX {
            let iso = timings.time("vpl energy", || {
                let j = ScatteringGrid { dims: merged.j.dims, index_to_world: merged.j.index_to_world, data: gathered.iso };
                let mut iso = upsample(&Merged { j, density: merged.density.clone() })?;
                // Its power as the host will render it: the same node values as S's (below).
                crate::lattice_product::finish(medium, &mut iso);
                Ok::<_, Error>(iso)
            })?;
            Some(energy::normalize(&mut scattering, &iso, &walks))
        } else {
            None
        };
        // On the CPU, in a session, the parts of the single scattering whose lights did not change are kept.
        let single = timings.time("vpl single scattering", || match ctx.on_device() {
            true => backend.single_scattering(scene, s, progress),
            false => ctx.single_scattering(scene, s.output_resolution, s.dome_directions, s.dome_spacing, counters),
        })?;
        debug_assert_eq!(single.dims, scattering.dims);
        for (a, b) in scattering.data.iter_mut().zip(&single.data) {
            *a += *b;
        }
        timings.time("vpl lattice product", || crate::lattice_product::finish(medium, &mut scattering));
        progress.update("vpl upsample", 1.0);
        let report = VplReport { walks: s.walks, near_field: s.near_field, vpls: walks.vpls.len(), vpl_power: walks.total_power().to_array(), walks_cut: walks.cut, gather: gstats, energy };
        Ok((SolveOutput::new(scattering, timings), report))
    }

    /// The near field this solve uses: the setting, `auto` resolved for `medium`: the hat where
    /// the medium's scattering-weighted optical radius at `gather::AUTO_CELLS` cells
    /// (`gather::scattering_optical_radius`) is above `gather::HAT_ABOVE`, else the ball
    /// (settings.rs `NearField::Auto`). A property of the medium, not of the settings, so that
    /// a medium gets the same kernel at every preset.
    pub fn near_field_for(&self, medium: &crate::medium::Medium) -> Result<NearField> {
        let s = &self.settings;
        if s.near_field != NearField::Auto {
            return Ok(s.near_field);
        }
        Ok(if gather::optical_size(medium)? > gather::HAT_ABOVE { NearField::Hat } else { NearField::Ball })
    }
}

impl Solver for Vpl {
    fn name(&self) -> &'static str {
        "vpl"
    }
    /// S with what the solve did (`VplReport`) attached; the gather, upsampling and single
    /// scattering on the device's `VplBackend` when the context carries one.
    fn solve(&self, scene: &Scene, ctx: &mut SolveCtx) -> Result<SolveOutput> {
        let backend: &dyn VplBackend = ctx.backend::<dyn VplBackend>().unwrap_or(&CpuBackend);
        let mut counters = Counters::default();
        let (out, report) = self.run(scene, ctx, backend, &mut counters)?;
        Ok(out.with_counters(counters).with_report(report))
    }
}

#[cfg(test)]
mod tests;
