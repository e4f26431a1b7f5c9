//! Initialisation of a radial grid: one sweep outwards along every column, as init.rs does
//! along a distant light's columns, and with the same split of the light (see init.rs's
//! departure): the *unscattered* light is exact (intensity x 1/r^2 x transmittance from the
//! emitter), and only the power it loses to scattering in a cell is injected as a packet, with
//! the anisotropy of once-scattered light, a = a_direct g.
//!
//! Packets are *power* (W) per cell, not radiance: the power a column carries does not change
//! as its cells grow outwards, so moving it along the principal (radial) direction needs no
//! rescaling, and the fluence it stands for in a cell, power x path / volume, falls off as
//! 1/r^2 by itself. This is the paper's "radiance scaled in proportion to the radial spacing"
//! (Sec. 6) done once, exactly, at accumulation.
//!
//! Columns start at the emitter (its radius for a sphere light): the stretch between it and
//! the innermost shell, when the grid leaves one out (grid.rs), is ray marched through the
//! full-resolution density, and what scatters there is injected into the innermost cell.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::grid::RadialGrid;
use crate::stages::octahedral::square_to_sphere;
use crate::medium::Medium;
use crate::translate::Profile;

/// What the sweep needs of the emitter.
#[derive(Clone, Copy, Debug)]
pub struct Emitter {
    pub intensity: Vec3,
    pub profile: Profile,
    /// Radius of a sphere light (light starts there and arrives in a cone); 0 for a point.
    pub radius: f32,
    /// Radius of the patch a VPL stands for (paper 03's clamping, see radial/mod.rs): its
    /// light arrives in the cone that patch subtends, and its inverse-square law stops there.
    /// 0 for a true point or sphere light.
    pub clamp_radius: f32,
    /// A sphere lamp's interior (docs/scene-format.md), None for other emitters: lit, J inside
    /// it is half the surface's radiance, I / (2 pi radius^2), from every direction; dark, none.
    pub lamp_interior: Option<crate::scene::SphereInterior>,
}

impl Emitter {
    /// Mean cosine of the unscattered light at distance r about the radial direction: the cone
    /// of half-angle asin(rho / r) that the sphere (or VPL patch) of radius rho subtends.
    pub fn anisotropy_at(&self, r: f32) -> f32 {
        let rho = self.radius.max(self.clamp_radius);
        if rho <= 0.0 {
            return 1.0;
        }
        let sin2 = (rho * rho / (r * r).max(1e-30)).min(1.0);
        0.5 * (1.0 + (1.0 - sin2).sqrt())
    }

    /// Fluence of the unscattered light at distance r, before attenuation, per unit profile
    /// factor: I / r^2 for a point; for a sphere light its radiance I / (pi rho^2) times the
    /// cone's solid angle 2 pi (1 - cos theta), which tends to I / r^2 far away.
    pub fn fluence_at(&self, r: f32) -> Vec3 {
        if self.radius > 0.0 {
            let sin2 = (self.radius * self.radius / (r * r).max(1e-30)).min(1.0);
            let one_minus_cos = sin2 / (1.0 + (1.0 - sin2).sqrt());
            self.intensity * (2.0 * one_minus_cos / (self.radius * self.radius))
        } else {
            let re = r.max(self.clamp_radius).max(1e-12);
            self.intensity / (re * re)
        }
    }
}

pub struct RadialInitial {
    /// Fluence of the unscattered light at each cell centre (W/m^2).
    pub direct: Vec<Vec3>,
    /// Its mean cosine about the radial direction (the initial anisotropy), per cell.
    pub a_direct: Vec<f32>,
    /// Power scattered out of the beam in each cell (W).
    pub packets: Vec<Vec3>,
    /// Power emitted, leaving the grid unscattered, and absorbed before scattering (W).
    pub entering: Vec3,
    pub transmitted: Vec3,
    pub absorbed: Vec3,
}

/// Mean profile factor over each column (4 x 4 sub-directions; equal area makes the plain mean
/// the solid-angle mean), so a sharp spot cone keeps its power.
fn column_factors(grid: &RadialGrid, profile: &Profile) -> Vec<f32> {
    let n = grid.n();
    const SUB: u32 = 4;
    (0..n * n)
        .into_par_iter()
        .map(|c| {
            let (i, j) = (c % n, c / n);
            let mut f = 0.0;
            for b in 0..SUB {
                for a in 0..SUB {
                    let p = Vec2::new(i as f32 + (a as f32 + 0.5) / SUB as f32, j as f32 + (b as f32 + 0.5) / SUB as f32) / n as f32;
                    f += profile.factor(square_to_sphere(p));
                }
            }
            f / (SUB * SUB) as f32
        })
        .collect()
}

/// Optical depth along `dir` from the emitter's surface to the innermost shell, marched
/// through the full-resolution density (half-voxel steps, at most 2048).
fn inner_optical_depth(medium: &Medium, centre: Vec3, dir: Vec3, r0: f32, r1: f32) -> Vec3 {
    if r1 <= r0 {
        return Vec3::ZERO;
    }
    let vs = medium.voxel_size_world().min_element();
    let steps = ((r1 - r0) / (0.5 * vs)).ceil().clamp(1.0, 2048.0) as u32;
    let dt = (r1 - r0) / steps as f32;
    let mut dens = 0.0;
    for s in 0..steps {
        dens += medium.density_world(centre + dir * (r0 + (s as f32 + 0.5) * dt));
    }
    medium.sigma_t(dens * dt)
}

/// One column's sweep: direct fluence and packets per shell, and its power emitted,
/// transmitted and absorbed.
struct ColumnSweep {
    direct: Vec<Vec3>,
    packets: Vec<Vec3>,
    entering: Vec3,
    transmitted: Vec3,
    absorbed: Vec3,
}

pub fn sweep(grid: &RadialGrid, medium: &Medium, e: &Emitter) -> RadialInitial {
    let slab = grid.slab();
    let nk = grid.shells();
    let omega = grid.cell_solid_angle();
    let factors = column_factors(grid, &e.profile);
    // sigma_s / sigma_t of the medium (constant: both scale with the density).
    let albedo = medium.sigma_s(1.0) / medium.sigma_t(1.0).max(Vec3::splat(1e-30));
    let a_shell: Vec<f32> = (0..nk).map(|k| e.anisotropy_at(grid.mid_radius(k))).collect();
    let mut direct = vec![Vec3::ZERO; grid.len()];
    let mut packets = vec![Vec3::ZERO; grid.len()];
    // Column by column (each writes only its own cells: strided, so collected then scattered).
    let columns: Vec<ColumnSweep> = (0..slab)
        .into_par_iter()
        .map(|c| {
            let mut dir_col = vec![Vec3::ZERO; nk];
            let mut pk_col = vec![Vec3::ZERO; nk];
            let power = e.intensity * (factors[c] * omega);
            if power.max_element() <= 0.0 {
                return ColumnSweep { direct: dir_col, packets: pk_col, entering: Vec3::ZERO, transmitted: Vec3::ZERO, absorbed: Vec3::ZERO };
            }
            let dir = grid.cols.directions[c];
            let tau0 = inner_optical_depth(medium, grid.centre, dir, e.radius, grid.radii[0]);
            let lost0 = power * (Vec3::ONE - (-tau0).exp());
            pk_col[0] += lost0 * albedo;
            let mut absorbed = lost0 - lost0 * albedo;
            let mut tau = tau0;
            for k in 0..nk {
                let cell = c + slab * k;
                let (ss, sa) = (grid.sigma_s[cell], grid.sigma_a[cell]);
                let st = ss + sa;
                let h = grid.thickness(k);
                let t_entry = (-tau).exp();
                dir_col[k] = e.fluence_at(grid.mid_radius(k)) * factors[c] * t_entry * (-st * (0.5 * h)).exp();
                let lost = power * t_entry * (Vec3::ONE - (-st * h).exp());
                let frac_s = Vec3::select(st.cmpgt(Vec3::splat(1e-12)), ss / st.max(Vec3::splat(1e-12)), Vec3::ZERO);
                pk_col[k] += lost * frac_s;
                absorbed += lost - lost * frac_s;
                tau += st * h;
            }
            ColumnSweep { direct: dir_col, packets: pk_col, entering: power, transmitted: power * (-tau).exp(), absorbed }
        })
        .collect();
    let (mut entering, mut transmitted, mut absorbed) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    for (c, col) in columns.into_iter().enumerate() {
        for k in 0..nk {
            direct[c + slab * k] = col.direct[k];
            packets[c + slab * k] = col.packets[k];
        }
        entering += col.entering;
        transmitted += col.transmitted;
        absorbed += col.absorbed;
    }
    let a_direct = (0..grid.len()).map(|i| a_shell[i / slab]).collect();
    RadialInitial { direct, a_direct, packets, entering, transmitted, absorbed }
}
