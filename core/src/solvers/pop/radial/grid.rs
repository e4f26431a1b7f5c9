//! The propagation domain of one point emitter (paper 01 Sec. 6, Fig. 2 bottom): shells around
//! the emitter times the octahedral columns of octahedral.rs. Cell (i, j, k) = column i + n j,
//! shell k (slowest, so a shell is one contiguous slab, like a depth slice of a light grid).
//!
//! Shell spacing grows exponentially, R_k = r_in q^k, with q chosen so that a cell's radial
//! length equals its angular width at its mid radius (cells as near cubic as the map allows,
//! which is what the 45-degree cones of the propagation assume). The shells span the medium
//! as seen from the emitter: from the nearest point of its bounds (or the emitter's radius, or
//! the clamp radius of a VPL) to the farthest corner; when that needs more than `max_shells`
//! shells, the innermost ball is left out of the grid (its light is marched exactly, see
//! init.rs) by raising r_in.

use glam::{IVec3, Vec2, Vec3};
use rayon::prelude::*;

use crate::stages::octahedral::{self, Columns};
use crate::error::{Error, Result};
use crate::medium::trilinear::trilinear;
use crate::medium::Medium;
use crate::stages::mip::MediumMip;

pub struct RadialGrid {
    pub centre: Vec3,
    pub cols: Columns,
    /// Shell boundaries R_0 .. R_nk (metres), R_{k+1} = q R_k.
    pub radii: Vec<f32>,
    pub q: f32,
    /// Per cell: scattering and absorption coefficients (1/m, RGB), cell averages.
    pub sigma_s: Vec<Vec3>,
    pub sigma_a: Vec<Vec3>,
}

impl RadialGrid {
    /// `n` angular cells per side (even), shells from at least `r_min` (emitter radius or
    /// clamp radius; 0 for a point), at most `max_shells`.
    pub fn new(medium: &Medium, mip: &MediumMip, centre: Vec3, n: u32, r_min: f32, max_shells: u32) -> Result<Self> {
        if n < 4 || !n.is_multiple_of(2) {
            return Err(Error::InvalidArgument(format!("radial grid: n must be even and >= 4, got {n}")));
        }
        let (lo, hi) = medium.world_bounds();
        let nearest = (centre.clamp(lo, hi) - centre).length();
        let mut farthest = 0.0f32;
        for c in 0..8 {
            let corner = Vec3::new(if c & 1 == 0 { lo.x } else { hi.x }, if c & 2 == 0 { lo.y } else { hi.y }, if c & 4 == 0 { lo.z } else { hi.z });
            farthest = farthest.max((corner - centre).length());
        }
        // Solid angle of a cell, and the growth that makes radial length = angular width:
        // (q - 1) R = s (q + 1) R / 2.
        let s = (4.0 * std::f32::consts::PI).sqrt() / n as f32;
        let q = (1.0 + 0.5 * s) / (1.0 - 0.5 * s);
        let floor = farthest * 1e-4;
        let mut r_in = nearest.max(r_min).max(floor);
        let r_out = farthest.max(r_in * q);
        let max_shells = max_shells.max(1);
        let mut shells = ((r_out / r_in).ln() / q.ln()).ceil().max(1.0) as u32;
        if shells > max_shells {
            shells = max_shells;
            r_in = r_out / q.powi(shells as i32);
        }
        let radii: Vec<f32> = (0..=shells).map(|k| r_in * q.powi(k as i32)).collect();
        let cols = Columns::new(n);
        let slab = (n * n) as usize;
        let count = slab * shells as usize;
        if count > 1 << 26 {
            return Err(Error::TooLarge(format!("pop radial grid {n}x{n}x{shells}")));
        }
        let voxel = medium.voxel_size_world().min_element();
        let w2i = medium.world_to_index;
        crate::budget::check(&format!("pop radial grids of {n}x{n}x{shells} cells (solver.radial_resolution)"), (count as u64).saturating_mul(96))?;
        let mut density = vec![0.0f32; count];
        density.par_chunks_mut(slab).enumerate().for_each(|(k, out)| {
            let (r0, r1) = (radii[k], radii[k + 1]);
            let footprint = (r1 - r0) / voxel;
            for (c, o) in out.iter_mut().enumerate() {
                let x = centre + cols.directions[c] * (0.5 * (r0 + r1));
                *o = mip.sample(medium, w2i.transform_point3(x), footprint);
            }
        });
        let sigma_s = density.iter().map(|&r| medium.sigma_s(r)).collect();
        let sigma_a = density.iter().map(|&r| (medium.sigma_t(r) - medium.sigma_s(r)).max(Vec3::ZERO)).collect();
        Ok(RadialGrid { centre, cols, radii, q, sigma_s, sigma_a })
    }

    pub fn n(&self) -> u32 {
        self.cols.n
    }
    pub fn shells(&self) -> usize {
        self.radii.len() - 1
    }
    pub fn slab(&self) -> usize {
        (self.cols.n * self.cols.n) as usize
    }
    pub fn len(&self) -> usize {
        self.slab() * self.shells()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Solid angle of one column (sr).
    pub fn cell_solid_angle(&self) -> f32 {
        4.0 * std::f32::consts::PI / self.slab() as f32
    }
    /// Mid radius of shell k.
    #[inline]
    pub fn mid_radius(&self, k: usize) -> f32 {
        0.5 * (self.radii[k] + self.radii[k + 1])
    }
    /// Radial length of shell k's cells (their edge h).
    #[inline]
    pub fn thickness(&self, k: usize) -> f32 {
        self.radii[k + 1] - self.radii[k]
    }
    /// Volume of a cell of shell k (m^3).
    #[inline]
    pub fn volume(&self, k: usize) -> f32 {
        self.cell_solid_angle() / 3.0 * (self.radii[k + 1].powi(3) - self.radii[k].powi(3))
    }
    #[inline]
    pub fn position(&self, c: usize) -> Vec3 {
        let slab = self.slab();
        self.centre + self.cols.directions[c % slab] * self.mid_radius(c / slab)
    }

    /// Lookup of a per-cell field at a world point: bilinear over the folded square, linear in
    /// log r between shell mid radii (constant inside the innermost and outside the outermost
    /// mid radius), zero beyond the outer shell. With `inverse_square`, for a field that falls
    /// off as 1/r^2 (the unscattered light's), r^2 x field is interpolated and divided by
    /// max(r, r_clamp)^2, so the inverse-square law near the emitter is exact rather than
    /// smeared over a cell.
    pub fn sample(&self, field: &[Vec3], w: Vec3, inverse_square: bool, r_clamp: f32) -> Vec3 {
        let to = w - self.centre;
        let r = to.length();
        let nk = self.shells();
        if nk == 0 || r >= self.radii[nk] {
            return Vec3::ZERO;
        }
        let n = self.cols.n as i32;
        let dir = if r > 0.0 { to / r } else { Vec3::Z };
        let p = octahedral::sphere_to_square(dir) * n as f32 - Vec2::splat(0.5);
        // Continuous shell coordinate: shell k's mid radius sits at k (log-spaced).
        let r_mid0 = self.mid_radius(0);
        let sk = if r <= r_mid0 { 0.0 } else { ((r / r_mid0).ln() / self.q.ln()).min((nk - 1) as f32) };
        let slab = self.slab();
        // Bilinear over the folded square (neighbours across its border through `wrap`), linear
        // between shells: one trilinear lookup with the shell index as third coordinate.
        let at = |c: IVec3| -> Vec3 {
            let (i, j) = octahedral::wrap(c.x, c.y, n);
            let k = (c.z.max(0) as usize).min(nk - 1);
            let v = field[(i + self.cols.n * j) as usize + slab * k];
            if inverse_square {
                let r_mid = self.mid_radius(k);
                v * (r_mid * r_mid)
            } else {
                v
            }
        };
        let v = trilinear(Vec3::new(p.x, p.y, sk), at);
        if inverse_square {
            let re = r.max(r_clamp).max(1e-6);
            v / (re * re)
        } else {
            v
        }
    }
}
