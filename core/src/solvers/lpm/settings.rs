//! Settings of `lpm`, read from the scene JSON's `solver` block and `--set KEY=VALUE`, and its
//! registry entry. Unknown keys are an error (a typo must not silently fall back to a default).
//! The measurements behind the defaults: docs/solvers/lpm.md.

use crate::error::{Error, Result};
use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::setting_choices! {
    /// First scattering of distant lights.
    pub enum FirstOrder {
        /// Transmittance marched to every cell, like POP's exact sweep.
        Exact = "exact",
        /// The paper: the sun is radiance E / solid angle in its direction bin at the boundary.
        Boundary = "boundary",
    }
}

crate::setting_choices! {
    /// What the delta-M split leaves the direction bins (delta_m.rs).
    pub enum PeakSplit {
        /// Wiscombe's: the peak f = g^2, the rest a Henyey-Greenstein lobe of g / (1 + g).
        Hg = "hg",
        /// The true lobe flattened above a cone fitted to the bins: the rest keeps the true
        /// phase function's sideways and backward scattering.
        Flattened = "flattened",
    }
}

crate::settings! {
    pub struct LpmSettings {
        /// The propagation costs cells x 6 x `directions` per order; 32 keeps an order of the
        /// 64-voxel plume near 0.1 s on one core.
        grid_resolution: u32 = 32, range(>= 2, <= 512),
            "cells of the propagation grid along the longest side";
        /// A k x k lattice over each face. Fewer shows the ray effect; more costs linearly per
        /// order, and the 6n x 6n phase table quadratically (256 is its cap).
        directions: u32 = 25, range(>= 1, <= 256),
            "propagation directions per cube face (a perfect square; the paper's 25)";
        /// With delta-M on, the paper's 6 bins (1 per face) are close on most scenes at the
        /// least cost; 54 (3, the final preset's) carry the flattened peak's lobe
        /// (`peak_split`), which 6 bins flatten, at about 2x the time. Above sqrt(directions) it
        /// acts as sqrt(directions).
        storage_per_face: u32 = 1, range(>= 1, <= 32),
            "storage directions m = 6 x this^2 (1: the paper's 6; 3, the final preset's, carries the flattened peak's lobe: dense clouds under a sun)";
        /// Fattal's criterion, relative so that it does not depend on the lights' units.
        epsilon: f32 = 1e-3, range(> 0, < 1),
            "stop when an order's largest U falls below this fraction of the first order's";
        /// A thick white medium converges slowly: the furnace cloud needs hundreds.
        max_orders: u32 = 200, range(>= 1, <= 100_000),
            "cap on propagated orders";
        /// Exact is closer (tests.rs).
        first_order: FirstOrder = FirstOrder::Exact,
            "first scattering of distant lights: exact transmittance to every cell, or the paper's boundary radiance in one bin";
        /// delta_m.rs: the peak's light goes on unscattered through sigma_t (1 - albedo f), and U
        /// scatters with the residual lobe g / (1 + g), which the 16-degree direction bins can
        /// represent; S's single scattering keeps the true medium. Also 3-4x fewer orders.
        delta_m: bool = true,
            "delta-M split of the phase function's forward peak (f = g^2): the peak's light goes on unscattered, the direction bins carry the broad rest";
        /// The HG residual scatters more light sideways and back than the true lobe; the
        /// flattened one does not, but it is only as close as the storage bins carry the lobe
        /// below its cap (docs/solvers/lpm.md, "The flattened peak").
        peak_split: PeakSplit = PeakSplit::Hg,
            "what the delta-M split leaves the bins: hg (a Henyey-Greenstein lobe of g / (1 + g)) or flattened (the true lobe with its peak cut off flat; closer with 3 or more storage bins a face side)";
        /// Sec. 4.2. Refused with the size needed when a one-layer slice does not fit.
        memory_budget: u64 = 0,
            "bytes for the propagation's slice buffers, which set the slice thickness (with out_of_core: everything a slice holds; 0: one slice)";
        /// out_of_core.rs: the per-cell arrays (sigma_t, density, U of two orders, J) in scratch
        /// files in `TMPDIR`, read and written a slab at a time; same J as in memory, to the bit.
        out_of_core: bool = false,
            "keep the per-cell arrays in scratch files a slab at a time, so that memory_budget bounds the whole solve (CPU, first_order boundary, no local lights)";
        output_resolution: u32 = 64, range(>= 2, <= 1024),
            "largest side of the returned scattering grid";
        /// A dense cloud's light falls by e^2 across a voxel of its lit face, which S's points
        /// at the voxel centres cannot carry (docs/solvers/lpm.md, "Two points a voxel").
        points_per_voxel: u32 = 2, range(>= 1, <= 4),
            "grid points a voxel of the returned grid, where output_resolution has room for them (a medium of fewer voxels)";
        /// pop's upsample.rs.
        upsample: bool = true,
            "joint bilateral upsampling guided by the density (off: trilinear)";
        range_sigma: f32 = 0.25, range(> 0),
            "range sigma of the bilateral filter, a fraction of the largest density";
        /// 0: J is deterministic and, in a medium a free path or more thick a cell, changes
        /// across a cell; a Gaussian moved the lit face's light inward (docs/solvers/lpm.md,
        /// "J interpolated, not smoothed").
        spatial_sigma: f32 = 0.0, range(>= 0, <= 4),
            "spatial sigma of the bilateral filter, in propagation cells (0: trilinear weights, J interpolated between the cells, not smoothed)";
        /// For a medium of g <= 0.5; `dome_directions_for` takes more for a forward lobe.
        dome_directions: u32 = 32, range(>= 1, <= 1024),
            "dome directions of the exact single scattering (g up to 0.5; a forward-scattering medium takes up to 8x more)";
    }
    check = cross_checks;
}

/// `directions` is a k x k lattice per face.
fn cross_checks(s: &LpmSettings) -> Result<()> {
    let k = s.lattice_side();
    if k * k != s.directions {
        return Err(Error::scene("solver.directions", format!("must be a perfect square (k x k per face), got {}", s.directions)));
    }
    Ok(())
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "lpm",
    label: "Light Propagation Maps",
    help: "light propagation maps (paper 05): deterministic discrete ordinates, every order to a threshold, streamed in slices under a memory budget (also for media larger than memory)",
    settings: LpmSettings::SETTINGS,
    defaults: defaults_of::<LpmSettings>,
    lights: &LightType::ALL,
    presets: &[
        // The interactive preset: under 0.15 s a frame for the 64^3 plume on 2 cores at 7% image
        // error (BENCHMARKS.md, "lpm draft (interactive)").
        Preset::draft(r#"{"grid_resolution": 12, "directions": 4, "output_resolution": 24, "dome_directions": 8}"#),
        Preset::preview(r#"{"grid_resolution": 32, "directions": 25, "output_resolution": 64}"#),
        // 64 cells and 49 directions took over 30 s on most of the scene set's 40 x 30 scenes
        // (issue 36): this one costs a few times the preview (BENCHMARKS.md `solvers`). The
        // flattened peak keeps the true lobe's back scattering (`peak_split`), and nine storage
        // bins a face carry its lobe, which one bin a face flattens (docs/solvers/lpm.md, "The
        // flattened peak", "The view rows").
        Preset::final_(r#"{"grid_resolution": 40, "directions": 36, "output_resolution": 96, "storage_per_face": 3, "peak_split": "flattened"}"#),
    ],
    // furnace.rs's (its bounds were measured with them).
    test: Preset::test(r#"{"grid_resolution": 16, "output_resolution": 16}"#),
    make: Make::Solver(|m| Ok(Box::new(super::Lpm::from_settings(m)?))),
    gpu: true,
};

impl LpmSettings {
    /// Side k of the k x k direction lattice per face.
    pub fn lattice_side(&self) -> u32 {
        (self.directions as f64).sqrt().round() as u32
    }
}

impl LpmSettings {
    /// The settings of the shared upsampling stage (stages/upsample.rs), declared here with the
    /// same names and ranges as in every solver that upsamples.
    pub fn upsampling(&self) -> crate::stages::upsample::Upsampling {
        crate::stages::upsample::Upsampling { output_resolution: self.output_size(), upsample: self.upsample, range_sigma: self.range_sigma, spatial_sigma: self.spatial_sigma }
    }

    /// The dome directions of the single scattering for a medium of mean cosine `g`. The fixed
    /// set follows the dome's brightness, not the phase function, and a forward lobe towards
    /// the camera narrower than the set's spacing falls between its directions: a cloud's
    /// sky-lit silhouette came out 2-3x off (docs/solvers/lpm.md, "The dome's directions").
    /// The lobe's solid angle goes as (1 - g)^2, so past g 0.5 the count grows as
    /// (0.5 / (1 - g))^2, up to 8x `dome_directions`.
    pub fn dome_directions_for(&self, g: f32) -> u32 {
        let lobe = (0.5 / (1.0 - g.clamp(-1.0, 0.999))).powi(2).clamp(1.0, 8.0);
        (self.dome_directions as f32 * lobe).round() as u32
    }

    /// The returned grid's size: `output_resolution` along the longest side, up to
    /// `points_per_voxel` points a voxel.
    pub fn output_size(&self) -> crate::stages::grid::GridSize {
        crate::stages::grid::GridSize { max_dim: self.output_resolution, points_per_voxel: self.points_per_voxel }
    }
}
