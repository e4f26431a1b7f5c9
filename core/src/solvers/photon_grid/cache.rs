//! The photon cache (Sec. 4.1.2): a coarse regular grid over the medium where photons leave
//! their flux at every tentative collision of Woodcock tracking. A solve keeps two, one per
//! lobe (mod.rs `SPLIT_ORDER`: once-scattered light, and the rest).
//!
//! Per cell: the density-weighted RGB flux sum (an unbiased estimate of the integral of
//! rho * fluence over the cell), the moment vector (sum of scalar deposit x direction of
//! travel), the scalar deposit sum, the photon-deposit count and the deposit-weighted
//! scattering order. Departures from the paper, both for several lights at once:
//! - the paper sums cosines to one dominant (sun) direction for the whole cloud; here each cell
//!   keeps a moment vector, its direction the cell's dominant direction and its length over the
//!   scalar sum the lobe's g' (the issue's "per-cell moment vector where several lights
//!   compete"). For one sun and the first orders that is the paper's quantity.
//! - sky photons are not kept out of the lobe: from a uniform sky their moments cancel, so they
//!   shorten the mean cosine (the isotropic part) instead of being a separate term.
//! - g' is the deposit-weighted mean cosine (the first moment of the radiance over the
//!   fluence, which a HG lobe matches), not the per-photon count average of the paper: with
//!   photons of unequal weight (albedo, spectral tracking) the count would weigh a spent
//!   photon like a fresh one.
//!
//! Why density-weighted: a deposit of rho(x) / majorant at each tentative collision sums to the
//! integral of rho along the track, so the cell holds the integral of rho * fluence, which
//! divided by the cell's integral of rho is the fluence where the medium is. A plain track
//! length over the cell volume would count only the part of the cell inside the majorant grid
//! and darken every cell that is partly empty.

use glam::{Affine3A, Vec3};

use super::fixed::{unfix, unfix3, FixedTallies};

use crate::error::Result;
use crate::medium::Medium;
use crate::stages::ScatteringGrid;

/// One cell's tallies (f32 within a batch; batches are summed in fixed point, fixed.rs).
#[derive(Clone, Copy, Debug, Default)]
pub struct Cell {
    pub flux: Vec3,
    pub moment: Vec3,
    pub weight: f32,
    pub order: f32,
    pub count: u32,
}

/// A cache frame with its tallies.
#[derive(Clone, Debug)]
pub struct Cache {
    /// The grid of cell centres (its data unused): `ScatteringGrid::over_medium`'s frame.
    pub frame: ScatteringGrid,
    pub world_to_cell: Affine3A,
    pub cells: Vec<Cell>,
}

impl Cache {
    pub fn new(medium: &Medium, resolution: u32) -> Result<Self> {
        let mut frame = ScatteringGrid::over_medium(medium, resolution)?;
        let cells = vec![Cell::default(); crate::budget::check_elements::<Cell>("photon cache (solver.cache_resolution)", frame.len() as u64)?];
        frame.data = Vec::new();
        let world_to_cell = frame.index_to_world.inverse();
        Ok(Cache { frame, world_to_cell, cells })
    }

    /// An empty cache on the same frame.
    pub fn empty_like(&self) -> Self {
        Cache { frame: self.frame.clone(), world_to_cell: self.world_to_cell, cells: vec![Cell::default(); self.cells.len()] }
    }

    /// The cell whose centre is nearest to world point `x`, if inside.
    #[inline]
    pub fn cell_of(&self, x: Vec3) -> Option<usize> {
        let p = self.world_to_cell.transform_point3(x).round();
        let d = self.frame.dims;
        if p.x < 0.0 || p.y < 0.0 || p.z < 0.0 || p.x >= d[0] as f32 || p.y >= d[1] as f32 || p.z >= d[2] as f32 {
            return None;
        }
        Some(self.frame.index(p.x as u32, p.y as u32, p.z as u32))
    }

    /// Leaves a photon's deposit: RGB `flux`, scalar `weight`, travelling along `dir` after
    /// `order` scatterings.
    #[inline]
    pub fn deposit(&mut self, x: Vec3, flux: Vec3, weight: f32, dir: Vec3, order: u32) {
        if let Some(i) = self.cell_of(x) {
            let c = &mut self.cells[i];
            c.flux += flux;
            c.moment += dir * weight;
            c.weight += weight;
            c.order += weight * order as f32;
            c.count += 1;
        }
    }
}

/// The cache's tallies summed over batches (and generations): per cell the integral of rho over
/// the cell (`mass`, world volume x density) and the totals. Everything a reconstruction
/// needs is a ratio of two of these, interpolated separately (mass-weighted interpolation).
#[derive(Clone, Debug)]
pub struct Tallies {
    pub frame: ScatteringGrid,
    pub world_to_cell: Affine3A,
    /// Integral of rho * fluence per cell (W/m^2 x density x m^3).
    pub flux: Vec<Vec3>,
    pub moment: Vec<Vec3>,
    pub weight: Vec<f32>,
    pub order: Vec<f32>,
    pub count: Vec<u32>,
    /// Integral of rho over the cell (density x m^3).
    pub mass: Vec<f32>,
}

impl Tallies {
    /// The fixed-point tallies `fixed` (fixed.rs: the sum of a solve's batches, or of the
    /// ring's generations) on `cache`'s frame, with each cell's mass measured in `medium`.
    /// Deposits carry each photon's power (the light's total over the photon count,
    /// `LightSampler`'s convention) already.
    pub fn from_fixed(medium: &Medium, cache: &Cache, fixed: &FixedTallies) -> Self {
        Tallies::with_mass(cache, fixed, cell_mass(medium, &cache.frame))
    }

    /// As `from_fixed`, with each cell's mass given (`cell_mass` on `cache`'s frame): a solve
    /// makes it once for both lobes, a session once while the medium stays.
    pub fn with_mass(cache: &Cache, fixed: &FixedTallies, mass: Vec<f32>) -> Self {
        let cells = &fixed.cells;
        Tallies {
            frame: cache.frame.clone(),
            world_to_cell: cache.world_to_cell,
            flux: cells.iter().map(|c| unfix3(&c.flux)).collect(),
            moment: cells.iter().map(|c| unfix3(&c.moment)).collect(),
            weight: cells.iter().map(|c| unfix(c.weight) as f32).collect(),
            order: cells.iter().map(|c| unfix(c.order) as f32).collect(),
            count: cells.iter().map(|c| c.count.min(u32::MAX as u64) as u32).collect(),
            mass,
        }
    }
}

/// The integral of the density over each cache cell (the box of half a cell around each
/// centre), by the midpoint rule on sub-points spaced at most half a medium voxel apart.
pub fn cell_mass(medium: &Medium, frame: &ScatteringGrid) -> Vec<f32> {
    use rayon::prelude::*;
    let step_world = Vec3::new(
        frame.index_to_world.transform_vector3(Vec3::X).length(),
        frame.index_to_world.transform_vector3(Vec3::Y).length(),
        frame.index_to_world.transform_vector3(Vec3::Z).length(),
    );
    let voxel = medium.voxel_size_world();
    let sub = (2.0 * step_world / voxel).ceil().clamp(Vec3::ONE, Vec3::splat(16.0)).as_uvec3();
    let volume = frame.index_to_world.matrix3.determinant().abs();
    let per_point = volume / (sub.x * sub.y * sub.z) as f32;
    let [nx, ny, nz] = frame.dims;
    (0..nx * ny * nz)
        .into_par_iter()
        .map(|idx| {
            let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
            let mut s = 0.0f32;
            for c in 0..sub.z {
                for b in 0..sub.y {
                    for a in 0..sub.x {
                        let off = (Vec3::new(a as f32, b as f32, c as f32) + 0.5) / sub.as_vec3() - 0.5;
                        let p = frame.index_to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32) + off);
                        s += medium.density_world(p);
                    }
                }
            }
            s * per_point
        })
        .collect()
}
