//! The isotropic residuum (paper 01, Sec. 5.4, Eq. 9-10).
//!
//! Scattering makes light isotropic: a packet's anisotropy decays as a g^(sigma_s t). Once
//! it is near zero the ordinates' grids no longer carry any directional information, yet in a
//! high-albedo medium they would each keep iterating for hundreds of steps. So each ordinate
//! runs only m' iterations (Eq. 10), the energy still travelling in all of them is gathered
//! into one medium-aligned grid, and that single grid is propagated isotropically (a = 0)
//! until its residual is small. Cost: N grids x m' iterations + one grid x the rest, instead
//! of N grids x all iterations.
//!
//! Choices made here:
//! - m' per ordinate, not one for all: Eq. 10 with the anisotropy of that ordinate's
//!   propagated packets, a_hat = a0 g (the unscattered light is exact, init.rs, so the packets
//!   are born once scattered), and the mean scattering coefficient over the medium's cells in
//!   that grid; at least the grid's depth along its direction, as the paper advises, so that
//!   light from the first slice has crossed the medium.
//! - Eq. 10 takes one cell edge of path per iteration; propagate.rs's diffusion correction
//!   makes a directional iteration 0.75-1 cell edge, so m' is slightly optimistic for
//!   moderately anisotropic light. The paper's epsilon_a (default 0.1) absorbs that.
//! - Gathering: each remaining packet is splatted trilinearly at its cell centre into the
//!   residuum grid (weights sum to one, positions clamped into the grid, energy scaled by the
//!   ratio of cell cross-sections), so the gathered energy equals the ordinates' remaining
//!   energy exactly. The remaining anisotropy (small by construction, reported in
//!   `PropagationStats::residual_anisotropy`) is dropped: the packets become isotropic.
//! - The residuum grid is a `LightGrid` whose direction is the medium's z axis (its cells
//!   line up with the medium's box for an axis-aligned medium), with `MARGIN_CELLS` of empty
//!   space around the box; with a = 0 the direction does not matter to the propagation, and
//!   the same backend (CPU or GPU, backend.rs) propagates it.
//! - The packets handed over were already accumulated for the step they were about to take;
//!   the residuum's first iteration accumulates them for half a step again (its packets are
//!   treated as born in their cells, propagate.rs). That is half a step of hundreds, left as
//!   is so that the residuum is a light like any other to the backend.

use glam::{IVec3, Vec3};

use super::light_grid::LightGrid;
use crate::stages::mip::MediumMip;
use crate::error::Result;
use crate::medium::Medium;
use crate::stages::progress::Progress;

/// Empty cells around the medium's box in the residuum grid. Isotropic light that leaves the
/// medium random-walks in the lattice's empty cells and partly comes back (the lattice cannot
/// stream it away, see `PopSettings::vacuum_escape`), so how much empty space a grid has
/// changes the brightness; the lights' grids, rotated around the medium, have some. Measured
/// on the cube (g 0, albedo 1, one light, m' = its depth), mean image brightness over the
/// reference's: 0.80 with no margin, 0.95 with 2 cells, 1.09 with 4, 1.23 with 8; 1.10 without
/// the residuum. 2 cells: closest to the reference, and 1.95x the cells of a tight grid.
pub const MARGIN_CELLS: u32 = 2;

/// Eq. 10: iterations after which packets of anisotropy `a_hat` have decayed below `eps_a`
/// in a medium of mean scattering coefficient `sigma_s` and phase anisotropy `g`, one cell
/// edge `h` per iteration; at least `min_iterations`, at most `max_iterations`.
pub fn switch_iteration(a_hat: f32, g: f32, sigma_s: f32, h: f32, eps_a: f32, min_iterations: u32, max_iterations: u32) -> u32 {
    let a_hat = a_hat.abs();
    let g = g.abs();
    let m = if a_hat <= eps_a || g < 1e-6 {
        0.0
    } else if g >= 1.0 || sigma_s * h <= 0.0 {
        f32::INFINITY
    } else {
        (eps_a.ln() - a_hat.ln()) / g.ln() / (sigma_s * h)
    };
    (m.ceil().min(max_iterations as f32) as u32).max(min_iterations).min(max_iterations)
}

/// Mean scattering coefficient over the grid's cells that hold medium, the smallest over the
/// channels (the channel whose anisotropy decays slowest decides when to switch).
pub fn mean_sigma_s(grid: &LightGrid) -> f32 {
    let (sum, count) = grid.sigma_s.iter().filter(|s| s.max_element() > 0.0).fold((Vec3::ZERO, 0usize), |(s, c), x| (s + *x, c + 1));
    if count == 0 { 0.0 } else { (sum / count as f32).min_element() }
}

/// The medium-aligned grid the ordinates' remaining energy is gathered into.
pub struct Residuum {
    pub grid: LightGrid,
    /// Gathered packets (energy per cell in the grid's fluence units, as `init::Initial`).
    pub packets: Vec<Vec3>,
}

impl Residuum {
    pub fn new(medium: &Medium, mip: &MediumMip, resolution: u32, progress: &dyn Progress) -> Result<Self> {
        let axis = Vec3::from(medium.index_to_world.matrix3.z_axis).normalize_or(Vec3::Z);
        let grid = LightGrid::with_margin(medium, mip, axis, resolution, MARGIN_CELLS, progress)?;
        let packets = vec![Vec3::ZERO; grid.len()];
        Ok(Residuum { grid, packets })
    }

    /// Adds the packets `remaining` of grid `from` (see the module doc).
    pub fn gather(&mut self, from: &LightGrid, remaining: &[Vec3]) {
        let scale = (from.h / self.grid.h).powi(2);
        let dims = self.grid.dims.as_ivec3();
        let max = (dims - IVec3::ONE).as_vec3();
        let (nx, ny) = (from.dims.x as usize, from.dims.y as usize);
        for (c, p) in remaining.iter().enumerate() {
            if *p == Vec3::ZERO {
                continue;
            }
            let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
            let x = from.position(i as u32, j as u32, k as u32);
            let q = self.grid.world_to_index.transform_point3(x).clamp(Vec3::ZERO, max);
            let f = q.floor();
            let t = q - f;
            let base = f.as_ivec3();
            let e = *p * scale;
            for corner in 0..8 {
                let o = IVec3::new(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
                let w = (if o.x == 1 { t.x } else { 1.0 - t.x }) * (if o.y == 1 { t.y } else { 1.0 - t.y }) * (if o.z == 1 { t.z } else { 1.0 - t.z });
                if w == 0.0 {
                    continue;
                }
                let cc = (base + o).min(dims - IVec3::ONE);
                self.packets[self.grid.index(cc.x as u32, cc.y as u32, cc.z as u32)] += e * w;
            }
        }
    }

    /// Energy gathered so far, per cell cross-section of this grid.
    pub fn gathered(&self) -> Vec3 {
        self.packets.iter().copied().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 10 by hand: a_hat 0.9, g 0.9, eps 0.1, sigma_s h = 0.5: (ln 0.1 - ln 0.9) / ln 0.9
    /// / 0.5 = 41.7 -> 42; clamped below by the depth and above by the cap; isotropic packets
    /// or g = 0 switch at the minimum; g = 1 never (the cap).
    #[test]
    fn switch_iteration_follows_eq_10() {
        assert_eq!(switch_iteration(0.9, 0.9, 5.0, 0.1, 0.1, 10, 400), 42);
        assert_eq!(switch_iteration(0.9, 0.9, 5.0, 0.1, 0.1, 50, 400), 50);
        assert_eq!(switch_iteration(0.9, 0.9, 5.0, 0.1, 0.1, 10, 30), 30);
        assert_eq!(switch_iteration(0.05, 0.9, 5.0, 0.1, 0.1, 10, 400), 10);
        assert_eq!(switch_iteration(0.9, 0.0, 5.0, 0.1, 0.1, 10, 400), 10);
        assert_eq!(switch_iteration(0.9, 1.0, 5.0, 0.1, 0.1, 10, 400), 400);
    }
}
