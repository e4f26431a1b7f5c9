//! The shared solver interface (DESIGN.md "What a solver returns"): every solver turns a
//! `Scene` into a scattering grid S(x) = sigma_s(x) * integral p(w_view, w') L(x, w') dw' —
//! in-scattered radiance per metre towards the camera, RGB, on a grid over the medium.

pub mod auto;
pub mod lpm;
pub mod network;
pub mod photon_grid;
pub mod pop;
pub mod reference;
pub mod guard;
pub mod registry;
pub mod session;
pub mod settings_table;
pub mod vpl;
#[cfg(test)]
pub(crate) mod testing;

use glam::{Affine3A, IVec3, Vec3};
use std::time::Instant;

use crate::error::{Error, Result};
use crate::medium::Medium;
use crate::scene::Scene;

/// Largest scattering grid a solver may allocate (512^3 points, 1.5 GiB of RGB floats).
pub const MAX_SCATTERING_GRID_POINTS: u64 = 1 << 27;

/// A dense RGB grid with its own index-to-world map (voxel centres at integer indices),
/// x fastest. Trilinear between voxel centres, zero outside.
#[derive(Clone, Debug)]
pub struct ScatteringGrid {
    pub dims: [u32; 3],
    pub index_to_world: Affine3A,
    pub data: Vec<Vec3>,
}

impl ScatteringGrid {
    /// An all-zero grid covering the medium's bounds: on the medium's own voxel grid when its
    /// extent fits in `max_dim` per axis, else on cells of k x k x k voxels.
    pub fn over_medium(medium: &Medium, max_dim: u32) -> Result<Self> {
        let (lo, hi) = medium.grid.bbox();
        if medium.grid.is_empty() {
            return Ok(ScatteringGrid { dims: [1, 1, 1], index_to_world: medium.index_to_world, data: vec![Vec3::ZERO] });
        }
        // Include the one-voxel trilinear ramp around the stored voxels.
        let lo = lo - IVec3::ONE;
        let hi = hi + IVec3::ONE;
        let extent = (hi - lo + IVec3::ONE).as_vec3();
        let k = (extent.max_element() / max_dim.max(2) as f32).max(1.0);
        let dims = (extent / k).ceil().as_uvec3().max(glam::UVec3::splat(2));
        let count = dims.x as u64 * dims.y as u64 * dims.z as u64;
        // Checked before allocating (an allocation failure aborts the host): 2^27 points is
        // 1.5 GiB of RGB, a 512^3 grid, beyond anything a preview needs.
        if count > MAX_SCATTERING_GRID_POINTS {
            return Err(Error::TooLarge(format!(
                "scattering grid {}x{}x{} = {count} points is over the limit of {MAX_SCATTERING_GRID_POINTS}",
                dims.x, dims.y, dims.z
            )));
        }
        crate::budget::check_elements::<Vec3>(&format!("scattering grid of {}x{}x{} points", dims.x, dims.y, dims.z), count)?;
        // Grid point i sits at medium index lo + i * step, spanning [lo, hi] exactly.
        let step = (hi - lo).as_vec3() / (dims.as_vec3() - Vec3::ONE);
        let index_to_world = medium.index_to_world * Affine3A::from_translation(lo.as_vec3()) * Affine3A::from_scale(step);
        Ok(ScatteringGrid { dims: dims.to_array(), index_to_world, data: vec![Vec3::ZERO; count as usize] })
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    #[inline]
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        (i as usize) + self.dims[0] as usize * (j as usize + self.dims[1] as usize * k as usize)
    }

    /// World position of grid point (i, j, k).
    pub fn position(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32))
    }

    /// Trilinear lookup at continuous grid-index coordinates; zero outside [0, dims - 1] (and
    /// for NaN).
    #[inline]
    pub fn sample_index(&self, p: Vec3) -> Vec3 {
        let d = IVec3::new(self.dims[0] as i32, self.dims[1] as i32, self.dims[2] as i32);
        if !crate::medium::trilinear::inside(p, Vec3::ZERO, (d - IVec3::ONE).as_vec3()) {
            return Vec3::ZERO;
        }
        crate::medium::trilinear::dense_inside(p, d, &self.data)
    }
}

/// Progress reports from a solver; `update` returns false to cancel. Called from the solver's
/// coordinating thread and from worker threads, hence `Sync`.
pub trait Progress: Sync {
    fn update(&self, stage: &str, fraction: f32) -> bool;

    /// True once the host has asked to stop (a cheap flag read, no callback): for loops too
    /// fine-grained to report progress from, which must still stop within ~100 ms of a cancel.
    fn cancelled(&self) -> bool {
        false
    }
}

/// Ignores progress, never cancels.
pub struct NoProgress;
impl Progress for NoProgress {
    fn update(&self, _: &str, _: f32) -> bool {
        true
    }
}

/// Wall-clock time of each phase, in seconds, in order.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timings(pub Vec<(String, f64)>);

impl Timings {
    pub fn time<T>(&mut self, phase: &str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let r = f();
        self.0.push((phase.to_string(), t.elapsed().as_secs_f64()));
        r
    }
}

pub struct SolveOutput {
    pub scattering: ScatteringGrid,
    pub timings: Timings,
    /// What the `auto` solver picked and why (None from every other solver).
    pub choice: Option<auto::Choice>,
}

impl SolveOutput {
    /// Build outputs with this, not a struct literal: fields added later (what a solver chose
    /// and why) then get their defaults without touching every solver.
    pub fn new(scattering: ScatteringGrid, timings: Timings) -> Self {
        SolveOutput { scattering, timings, choice: None }
    }
}

pub trait Solver: Send + Sync {
    fn name(&self) -> &'static str;
    fn solve(&self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput>;

    /// As `solve`, one frame of a sequence: the solver may read what it kept in `state` from
    /// the previous frames and keep more, but must return exactly what `solve` would for this
    /// scene (session.rs). The default keeps nothing.
    fn solve_in_session(&self, scene: &Scene, progress: &dyn Progress, state: &mut session::SessionState) -> Result<SolveOutput> {
        let _ = state;
        self.solve(scene, progress)
    }
}

pub use registry::SOLVER_NAMES;

/// Builds a solver from its name and the scene's `solver` settings block (through the
/// registry: unknown names are refused with the list of known ones).
pub fn by_name(name: &str, settings: &serde_json::Map<String, serde_json::Value>) -> Result<Box<dyn Solver>> {
    (registry::get(name)?.cpu)(settings)
}

/// Parses a solver's settings struct from the `solver` block, ignoring `name` and naming the
/// offending key in errors.
pub fn parse_settings<T: serde::de::DeserializeOwned>(settings: &serde_json::Map<String, serde_json::Value>) -> Result<T> {
    let mut map = settings.clone();
    map.remove("name");
    serde_path_to_error::deserialize(serde_json::Value::Object(map))
        .map_err(|e| Error::scene(format!("solver.{}", e.path()), e.into_inner().to_string()))
}
