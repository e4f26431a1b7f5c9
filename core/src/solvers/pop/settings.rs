//! Settings of `pop`, read from the scene JSON's `solver` block and `--set KEY=VALUE`.
//! Unknown keys are an error (a typo must not silently fall back to a default).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PopSettings {
    /// Cells along the longest side of each light's propagation grid. Cells are cubes (the
    /// solid-angle split of Eq. 3 assumes cubic cells), so the other sides get proportionally
    /// fewer. The paper uses 8^3 to 20^3 on a GPU.
    pub grid_resolution: u32,
    /// Cap on propagation iterations per light.
    pub max_iterations: u32,
    /// Stop when the energy still travelling in the propagation grid falls below this fraction
    /// of the energy that was scattered into it (the paper's epsilon_L, made relative).
    pub residual_threshold: f32,
    /// Largest side of the medium-aligned grid the lights are merged into (Sec. 5.3); 0 = twice
    /// `grid_resolution` (the paper's choice: propagation grids are rotated, so merging at
    /// the same resolution would undersample them).
    pub merge_resolution: u32,
    /// Largest side of the returned scattering grid (the medium's own voxels when it is
    /// smaller than this).
    pub output_resolution: u32,
    /// Joint bilateral upsampling guided by the density (Sec. 4.4). Off: trilinear.
    pub upsample: bool,
    /// Range sigma of the bilateral filter, as a fraction of the medium's largest density.
    pub range_sigma: f32,
    /// Spatial sigma of the bilateral filter, in merged-grid cells.
    pub spatial_sigma: f32,
    /// Correct the lattice's diffusion towards the physical one where light has become
    /// isotropic (see propagate.rs). Off: every iteration is one cell of light path, as in the
    /// paper.
    pub diffusion_correction: bool,
    /// Outside the medium (empty cells), the isotropic part of the light escapes instead of
    /// random-walking back into the medium (the lattice cannot stream it outwards). Off by
    /// default: measured, it helps dense clouds in empty space (default scene without sky: grid
    /// rel. RMSE 0.81 -> 0.64, grid mean 1.58x -> 1.39x the reference) but over-darkens a
    /// diffusive cube (g 0: image 0.18 -> 0.23, mean 1.10x -> 0.79x), because an empty cell
    /// one step outside acts as a perfect absorber, closer than the physical extrapolated
    /// boundary (0.71 / sigma_tr).
    pub vacuum_escape: bool,
    /// Each part of a cell's lobe (front, sides, back) leaves with the mean cosine about d of
    /// its own cone instead of the whole lobe's anisotropy, so light sent sideways or back is
    /// not re-aimed along d on arrival (the net flux along d is kept exactly, propagate.rs
    /// `lobe_moments`); and light in empty cells is re-emitted isotropically (with
    /// `vacuum_escape` it escapes instead). Off by default. Measured (docs/pop-dense-clouds.md):
    /// dense cloud image rel. RMSE 0.49 -> 0.25, flux 0.65x -> 1.02x (grid 1.07 -> 1.03);
    /// at 16 cells cube g 0.9 0.40 -> 0.30, plume 0.39 -> 0.35, cube g 0 0.17 -> 0.17, but
    /// cube g 0.7 0.25 -> 0.30. CPU only: the GPU backend propagates on the CPU when it is on.
    pub moment_anisotropy: bool,
    /// A dome is approximated by this many distant ordinates (Sec. 5, dome.rs): the sphere is
    /// cut into regions of equal importance (the dome's luminance, times the directional
    /// importance when `dome_importance` is on, mixed half and half with a uniform density),
    /// each ordinate carrying exactly its region's light, with the region's radiance-weighted
    /// mean cosine as initial anisotropy (Sec. 5.1). 0: the dome is left out of the
    /// scattering, with a warning. The paper uses 27 to 64.
    pub dome_ordinates: u32,
    /// Weight the choice of the dome's ordinates by how much light from each direction reaches
    /// the camera (importance propagation, Sec. 5.2, importance.rs): more ordinates where they
    /// are seen. Costs a few small propagations per solve. Measured (tests/dome_cases.rs,
    /// image error at N = 16 / 64 / 125): uniform dome 0.313 / 0.203 / 0.153 without, 0.298 /
    /// 0.157 / 0.143 with; sun sky 0.305 / 0.205 / 0.196 without, 0.354 / 0.227 / 0.215 with
    /// (it draws ordinates behind the medium, away from a sun on the camera's side).
    pub dome_importance: bool,
    /// Isotropic residuum (Sec. 5.4, residuum.rs): each light's grid runs only until its
    /// packets have become nearly isotropic (Eq. 10, or `residuum_iterations`), then the
    /// energy still travelling in all of them is gathered into one medium-aligned grid and
    /// propagated isotropically to convergence. Saves most of the iterations in high-albedo
    /// media with many ordinates, for a small change of the result (see the tests).
    pub isotropic_residuum: bool,
    /// The anisotropy below which light counts as isotropic, epsilon_a of Eq. 9-10 (the paper:
    /// "around 0.1, or even higher").
    pub residuum_anisotropy: f32,
    /// Iterations per light before switching to the residuum, m'; 0 = Eq. 10 per light (at
    /// least the grid's depth along the light).
    pub residuum_iterations: u32,
    /// Cells along the longest side of the residuum grid; 0 = the dome ordinates' resolution
    /// (`dome_grid_resolution`): isotropic light is smooth, and the lattice's isotropic
    /// diffusion needs iterations in proportion to the square of the resolution, so a grid
    /// twice as fine costs about 32 times as much.
    pub residuum_grid_resolution: u32,
    /// Propagation grid resolution of each dome ordinate; 0 = half of `grid_resolution`
    /// (sky light is smooth, and there are many ordinates).
    pub dome_grid_resolution: u32,
    // --- radial grids for local lights (radial/, paper Sec. 6) ---
    /// Angular cells per side of each local light's octahedral square (n x n columns of equal
    /// solid angle); 0 = `grid_resolution` (rounded up to even). Even, 4..=256.
    pub radial_resolution: u32,
    /// Most shells per radial grid; shells grow by 1 + 3.5 / n per step, so 64 shells span a
    /// radius ratio of about 1000 at n = 32 (the inner rest is ray marched).
    pub radial_max_shells: u32,
    /// An area light becomes `area_vpls` x `area_vpls` VPLs, each with its own radial grid.
    pub area_vpls: u32,
    /// An emissive medium (medium.emission) becomes this many VPLs of equal power, each with
    /// its own radial grid (the compositor's single-scattering AOV uses the medium's own,
    /// larger `vpls` count: a VPL there costs a shadow ray, here a whole grid).
    pub emission_vpls: u32,
    /// `vacuum_escape` for the radial grids, on by default there: light leaving a medium
    /// around a light must not random-walk back in. Measured (test settings): paper Fig. 10
    /// sphere at g 0, image rel. RMSE 0.48 (1.5x too bright) -> 0.17 and 3944 -> 3518
    /// iterations; lights beside the plume 0.31 -> 0.33 (2% darker) in 3x fewer iterations.
    pub radial_vacuum_escape: bool,
}

impl Default for PopSettings {
    fn default() -> Self {
        PopSettings {
            grid_resolution: 32,
            max_iterations: 400,
            residual_threshold: 1e-3,
            merge_resolution: 0,
            output_resolution: 128,
            upsample: true,
            range_sigma: 0.15,
            spatial_sigma: 0.8,
            diffusion_correction: true,
            vacuum_escape: false,
            moment_anisotropy: false,
            dome_ordinates: 16,
            dome_grid_resolution: 0,
            dome_importance: true,
            isotropic_residuum: true,
            residuum_anisotropy: 0.1,
            residuum_iterations: 0,
            residuum_grid_resolution: 0,
            radial_resolution: 0,
            radial_max_shells: 64,
            area_vpls: 3,
            emission_vpls: 8,
            radial_vacuum_escape: true,
        }
    }
}

impl PopSettings {
    pub fn validate(&self) -> Result<()> {
        if !(2..=512).contains(&self.grid_resolution) {
            return Err(Error::scene("solver.grid_resolution", format!("must be in 2..=512, got {}", self.grid_resolution)));
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err(Error::scene("solver.max_iterations", format!("must be in 1..=100000, got {}", self.max_iterations)));
        }
        if !(self.residual_threshold.is_finite() && self.residual_threshold >= 0.0 && self.residual_threshold < 1.0) {
            return Err(Error::scene("solver.residual_threshold", format!("must be in [0, 1), got {}", self.residual_threshold)));
        }
        if self.merge_resolution != 0 && !(2..=1024).contains(&self.merge_resolution) {
            return Err(Error::scene("solver.merge_resolution", format!("must be 0 or in 2..=1024, got {}", self.merge_resolution)));
        }
        self.upsampling().validate()?;
        if self.dome_ordinates > 1024 {
            return Err(Error::scene("solver.dome_ordinates", format!("must be in 0..=1024, got {}", self.dome_ordinates)));
        }
        if !(self.residuum_anisotropy.is_finite() && self.residuum_anisotropy > 0.0 && self.residuum_anisotropy < 1.0) {
            return Err(Error::scene("solver.residuum_anisotropy", format!("must be in (0, 1), got {}", self.residuum_anisotropy)));
        }
        if self.residuum_grid_resolution != 0 && !(2..=512).contains(&self.residuum_grid_resolution) {
            return Err(Error::scene("solver.residuum_grid_resolution", format!("must be 0 or in 2..=512, got {}", self.residuum_grid_resolution)));
        }
        if self.dome_grid_resolution != 0 && !(2..=512).contains(&self.dome_grid_resolution) {
            return Err(Error::scene("solver.dome_grid_resolution", format!("must be 0 or in 2..=512, got {}", self.dome_grid_resolution)));
        }
        if self.radial_resolution != 0 && !(4..=256).contains(&self.radial_resolution) {
            return Err(Error::scene("solver.radial_resolution", format!("must be 0 or in 4..=256, got {}", self.radial_resolution)));
        }
        if !(1..=1024).contains(&self.radial_max_shells) {
            return Err(Error::scene("solver.radial_max_shells", format!("must be in 1..=1024, got {}", self.radial_max_shells)));
        }
        if !(1..=256).contains(&self.emission_vpls) {
            return Err(Error::scene("solver.emission_vpls", format!("must be in 1..=256, got {}", self.emission_vpls)));
        }
        if !(1..=16).contains(&self.area_vpls) {
            return Err(Error::scene("solver.area_vpls", format!("must be in 1..=16, got {}", self.area_vpls)));
        }
        Ok(())
    }

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
