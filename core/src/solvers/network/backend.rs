//! Where `network`'s heavy stages run. `Network`'s solve builds the network (particles,
//! visibility, phase matrix) and the direct light, and hands the stages that touch every
//! (particle, direction) pair or every output cell to a `NetworkBackend`: the CPU code of this
//! module's siblings (`CpuBackend`), or the GPU port in volscatter-gpu (shaders/src/network/).
//! The backend receives the kept network by reference on every call, so a GPU backend uploads
//! it per frame (a session keeps it on the host; see mod.rs).

use glam::Vec3;

use super::iterate::{self, Iterated};
use super::particles::Particles;
use super::settings::Opacity;
use super::splat;
use super::visibility::{self, DirectionLinks};
use crate::error::{Error, Result};
use crate::medium::Medium;
use crate::stages::{Progress, ScatteringGrid};

/// What the visibility network is built from (visibility.rs `build`).
pub struct VisibilityInput<'a> {
    pub medium: &'a Medium,
    pub particles: &'a Particles,
    /// Directions light travels.
    pub dirs: &'a [Vec3],
    /// The bounding sphere the M x M windows cover.
    pub centre: Vec3,
    pub radius: f32,
    /// Window side M.
    pub window: u32,
    pub opacity: Opacity,
}

/// What the iteration of Eq. 2 reads (iterate.rs).
pub struct IterationInput<'a> {
    pub links: &'a [DirectionLinks],
    /// D x D row-normalised phase matrix, row-major.
    pub phase: &'a [f32],
    /// The direct light's first scattering E, N x D row-major.
    pub first: &'a [Vec3],
    pub albedo: Vec3,
    pub max_iterations: u32,
    pub threshold: f32,
}

/// What the splat reads (splat.rs).
pub struct SplatInput<'a> {
    pub medium: &'a Medium,
    pub particles: &'a Particles,
    /// I, N x D row-major.
    pub radiance: &'a [Vec3],
    pub dirs: &'a [Vec3],
    pub camera: Vec3,
    pub kernel_radius: f32,
    pub range_sigma: f32,
}

pub trait NetworkBackend {
    /// Per direction the particles' column order, upstream neighbours and opacities, as
    /// visibility.rs `build` defines them (same ties, same lists); `Error::Cancelled` once
    /// `progress` is cancelled.
    fn visibility(&self, input: &VisibilityInput, progress: &dyn Progress) -> Result<Vec<DirectionLinks>>;

    /// Iterates Eq. 2 from `start` (or zero) to the residual threshold; stops early, returning
    /// what it has, once `progress` is cancelled (the caller then discards it).
    fn iterate(&self, input: &IterationInput, start: Option<Vec<Vec3>>, progress: &dyn Progress) -> Result<Iterated>;

    /// Adds sigma_s x the particles' splatted radiance towards the camera into `grid`; may
    /// return `Error::Cancelled` once `progress` is cancelled.
    fn splat(&self, grid: &mut ScatteringGrid, input: &SplatInput, progress: &dyn Progress) -> Result<()>;
}

/// The CPU stages.
pub struct CpuBackend;

impl NetworkBackend for CpuBackend {
    fn visibility(&self, x: &VisibilityInput, progress: &dyn Progress) -> Result<Vec<DirectionLinks>> {
        visibility::build(x.medium, x.particles, x.dirs, x.centre, x.radius, x.window, x.opacity, progress).ok_or(Error::Cancelled)
    }

    fn iterate(&self, x: &IterationInput, start: Option<Vec<Vec3>>, progress: &dyn Progress) -> Result<Iterated> {
        Ok(iterate::iterate(x.links, x.phase, x.first, x.albedo, x.max_iterations, x.threshold, start, progress))
    }

    /// Not cancellable inside (as before the backend split): the solve looks before and after.
    fn splat(&self, grid: &mut ScatteringGrid, x: &SplatInput, _progress: &dyn Progress) -> Result<()> {
        let values = splat::towards_viewer(x.particles, x.radiance, x.dirs, x.medium.g, x.camera);
        splat::splat_into(grid, x.medium, x.particles, &values, x.kernel_radius, x.range_sigma);
        Ok(())
    }
}
