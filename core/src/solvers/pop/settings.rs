//! Settings of `pop`, read from the scene JSON's `solver` block and `--set KEY=VALUE`, and its
//! registry entry. Unknown keys are an error (a typo must not silently fall back to a
//! default). Measurements behind the defaults: docs/solvers/pop.md.

use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::settings! {
    pub struct PopSettings {
        /// Cells are cubes (the solid-angle split of Eq. 3 assumes cubic cells), so the other
        /// sides get proportionally fewer. The paper uses 8^3 to 20^3 on a GPU.
        grid_resolution: u32 = 32, range(>= 2, <= 512),
            "cells along the longest side of each light's propagation grid";
        max_iterations: u32 = 400, range(>= 1, <= 100_000),
            "cap on propagation iterations per light";
        /// The paper's epsilon_L, made relative so that it does not depend on the lights' units.
        residual_threshold: f32 = 1e-3, range(>= 0, < 1),
            "stop when the travelling energy falls below this fraction of the scattered";
        /// Sec. 5.3. Twice by default: propagation grids are rotated, so merging at the same
        /// resolution would undersample them.
        merge_resolution: u32 = 0, range(>= 2, <= 1024), zero("twice grid_resolution"),
            "largest side of the medium-aligned grid the lights are merged into";
        /// The medium's own voxels when it is smaller than this.
        output_resolution: u32 = 128, range(>= 2, <= 1024),
            "largest side of the returned scattering grid";
        /// Sec. 4.4.
        upsample: bool = true,
            "joint bilateral upsampling guided by the density (off: trilinear)";
        range_sigma: f32 = 0.15, range(> 0),
            "range sigma of the bilateral filter, a fraction of the largest density";
        spatial_sigma: f32 = 0.8, range(> 0, <= 4),
            "spatial sigma of the bilateral filter, in merged-grid cells";
        /// See propagate.rs. Off: every iteration is one cell of light path, as in the paper.
        diffusion_correction: bool = true,
            "match the lattice's diffusion to the physical one where light is isotropic";
        /// Off by default: an empty cell one step outside acts as a perfect absorber, closer
        /// than the physical extrapolated boundary, which helps dense clouds in empty space but
        /// over-darkens a diffusive cube.
        vacuum_escape: bool = false,
            "isotropic light leaving the medium escapes instead of random-walking back";
        /// Light sent sideways or back is then not re-aimed along d on arrival (the net flux
        /// along d is kept exactly, propagate.rs `lobe_moments`). Off by default: it helps
        /// dense clouds and hurts cube g 0.7. CPU only: the GPU backend propagates on the CPU
        /// when it is on.
        moment_anisotropy: bool = false,
            "each part of a lobe keeps its own mean cosine and empty cells re-emit isotropically (for dense clouds; CPU only)";
        /// Sec. 5, dome.rs: the sphere is cut into regions of equal importance, each ordinate
        /// carrying exactly its region's light with the region's mean cosine as initial
        /// anisotropy (Sec. 5.1). 0 leaves the dome out with a warning. The paper uses 27 to 64.
        dome_ordinates: u32 = 16, range(>= 0, <= 1024),
            "distant ordinates a dome is approximated by (0: the dome is left out)";
        /// Sky light is smooth, and there are many ordinates.
        dome_grid_resolution: u32 = 0, range(>= 2, <= 512), zero("half of grid_resolution, at least 8"),
            "propagation grid resolution of each dome ordinate";
        /// Importance propagation (Sec. 5.2, importance.rs): more ordinates where they are
        /// seen, for a few small propagations per solve.
        dome_importance: bool = true,
            "place the dome's ordinates by how much of their light reaches the camera";
        /// Sec. 5.4, residuum.rs: saves most of the iterations in high-albedo media with many
        /// ordinates, for a small change of the result.
        isotropic_residuum: bool = true,
            "finish nearly isotropic light in one shared isotropic grid";
        /// epsilon_a of Eq. 9-10 (the paper: "around 0.1, or even higher").
        residuum_anisotropy: f32 = 0.1, range(> 0, < 1),
            "anisotropy below which light counts as isotropic";
        /// m' of the paper; 0: Eq. 10 per light (at least the grid's depth along the light).
        residuum_iterations: u32 = 0, zero("Eq. 10 per light"),
            "iterations per light before the residuum takes over";
        /// Isotropic light is smooth, and the lattice's diffusion needs iterations in
        /// proportion to the square of the resolution: twice as fine costs ~32x.
        residuum_grid_resolution: u32 = 0, range(>= 2, <= 512), zero("dome_grid_resolution"),
            "cells along the longest side of the residuum grid";
        /// Radial grids for local lights (radial/, paper Sec. 6): n x n columns of equal solid
        /// angle; rounded up to even (the octahedral folding needs it).
        radial_resolution: u32 = 0, range(>= 4, <= 256), zero("grid_resolution"),
            "angular cells per side of each local light's octahedral grid (even)";
        /// Shells grow by 1 + 3.5 / n per step, so 64 shells span a radius ratio of about 1000
        /// at n = 32 (the inner rest is ray marched).
        radial_max_shells: u32 = 64, range(>= 1, <= 1024),
            "most shells per radial grid";
        /// Each VPL gets its own radial grid.
        area_vpls: u32 = 3, range(>= 1, <= 16),
            "an area light becomes area_vpls x area_vpls VPLs";
        /// Fewer than the compositor's single-scattering `vpls` of the medium: a VPL there
        /// costs a shadow ray, here a whole radial grid.
        emission_vpls: u32 = 8, range(>= 1, <= 256),
            "VPLs an emissive medium becomes";
        /// On by default there: light leaving a medium around a light must not random-walk
        /// back in.
        radial_vacuum_escape: bool = true,
            "vacuum_escape for the local lights' radial grids";
    }
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "pop",
    label: "Principal Ordinates",
    help: "principal-ordinates propagation (paper 01): light propagated on grids aligned with each light, deterministic, for thin to moderately dense media",
    settings: PopSettings::SETTINGS,
    defaults: defaults_of::<PopSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset::draft(r#"{"grid_resolution": 16, "max_iterations": 100, "output_resolution": 64}"#),
        Preset::preview(r#"{"grid_resolution": 32, "max_iterations": 400, "output_resolution": 128}"#),
        // The preview's grids converged further: a finer grid made pop's image worse, not better,
        // at 7-17x the time (issue 36; BENCHMARKS.md `solvers`, preset ladders on the scene set).
        Preset::final_(r#"{"grid_resolution": 32, "max_iterations": 1000, "residual_threshold": 0.0001, "output_resolution": 128}"#),
    ],
    // furnace.rs's (its bounds were measured with them); extreme.rs's grid too (its scenes have
    // no dome, and their 16^3 voxels cap the output at 16).
    test: Preset::test(r#"{"grid_resolution": 12, "dome_ordinates": 16, "dome_grid_resolution": 12}"#),
    make: Make::Solver(|m| Ok(Box::new(super::Pop::from_settings(m)?))),
    gpu: true,
};

impl PopSettings {
    /// Columns per side of a radial grid: even (the octahedral folding needs it), at least 4.
    pub fn radial_resolution(&self) -> u32 {
        let n = if self.radial_resolution == 0 { self.grid_resolution.min(256) } else { self.radial_resolution };
        (n + n % 2).max(4)
    }

    pub fn dome_grid_resolution(&self) -> u32 {
        if self.dome_grid_resolution == 0 { (self.grid_resolution / 2).max(8) } else { self.dome_grid_resolution }
    }

    pub fn residuum_grid_resolution(&self) -> u32 {
        if self.residuum_grid_resolution == 0 { self.dome_grid_resolution() } else { self.residuum_grid_resolution }
    }

    pub fn merge_resolution(&self) -> u32 {
        if self.merge_resolution == 0 { (2 * self.grid_resolution).min(1024) } else { self.merge_resolution }
    }
}

impl PopSettings {
    /// The settings of the shared upsampling stage (stages/upsample.rs), declared here with the
    /// same names and ranges as in every solver that upsamples.
    pub fn upsampling(&self) -> crate::stages::upsample::Upsampling {
        crate::stages::upsample::Upsampling { output_resolution: self.output_resolution.into(), upsample: self.upsample, range_sigma: self.range_sigma, spatial_sigma: self.spatial_sigma }
    }
}
