//! A participating medium: a density grid placed in the world by an affine index-to-world map,
//! with the material that turns density into coefficients (DESIGN.md "Scene model and units"):
//! `sigma_t = density_scale * density`, `sigma_s = albedo * sigma_t`, HG anisotropy `g`.

pub mod blackbody;
mod cie1931;
pub mod cumulus;
pub mod dense_march;
pub mod emission;
pub mod grid;
pub mod key;
pub mod majorant;
pub mod optics;
pub mod procedural;
pub mod raw;
pub mod tracking;
pub mod trilinear;

use glam::{Affine3A, IVec3, Vec3};

pub use emission::{Emission, EmissionLaw, EmissionTerm};
pub use grid::{DensityGrid, DensityGridBuilder, GridLimits};
pub use majorant::MajorantGrid;
pub use optics::{ball_mean_inverse_square, lamp_inverse_square, lamp_mean_over_ball, min_spacing, near_field_radius, optical_depth, ray_box};
pub use tracking::{FreeFlight, Tracking};

#[derive(Clone, Debug)]
pub struct Medium {
    pub grid: DensityGrid,
    /// Index space (voxel centres at integers) to world (metres).
    pub index_to_world: Affine3A,
    pub world_to_index: Affine3A,
    /// Extinction per unit density, per RGB channel (1/m). Usually grey; RGB for chromatic
    /// media such as paper 01's Fig. 10 sphere.
    pub density_scale: Vec3,
    pub albedo: Vec3,
    pub g: f32,
    /// Volume emission (fire), if any: see emission.rs.
    pub emission: Option<Emission>,
}

impl Medium {
    pub fn new(grid: DensityGrid, index_to_world: Affine3A, density_scale: Vec3, albedo: Vec3, g: f32) -> Self {
        Medium { grid, index_to_world, world_to_index: index_to_world.inverse(), density_scale, albedo, g, emission: None }
    }

    /// Index-space box outside which the density is exactly zero (one voxel of trilinear
    /// ramp around the stored voxels).
    pub fn index_bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.grid.bbox();
        ((lo - IVec3::ONE).as_vec3(), (hi + IVec3::ONE).as_vec3())
    }

    /// Axis-aligned world box containing the medium.
    pub fn world_bounds(&self) -> (Vec3, Vec3) {
        let (lo, hi) = self.index_bounds();
        optics::world_box(&self.index_to_world, lo, hi)
    }

    /// Density (unscaled) at a world point.
    #[inline]
    pub fn density_world(&self, p: Vec3) -> f32 {
        self.grid.sample(self.world_to_index.transform_point3(p))
    }

    #[inline]
    pub fn sigma_t(&self, density: f32) -> Vec3 {
        self.density_scale * density
    }

    #[inline]
    pub fn sigma_s(&self, density: f32) -> Vec3 {
        self.albedo * self.density_scale * density
    }

    /// Length of one voxel edge in world units along each index axis.
    pub fn voxel_size_world(&self) -> Vec3 {
        Vec3::new(
            self.index_to_world.transform_vector3(Vec3::X).length(),
            self.index_to_world.transform_vector3(Vec3::Y).length(),
            self.index_to_world.transform_vector3(Vec3::Z).length(),
        )
    }
}
