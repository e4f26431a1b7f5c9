//! Propagation in a radial grid: the rules of propagate.rs (Eq. 1-8) with the principal
//! direction of every cell radial outwards. A cell sends P F(a) to the cell outwards (front,
//! the 45-degree cone), to its four angular neighbours (side quarters of the band) and inwards
//! (back); absorption-only transmittance and the anisotropy decay a g^(sigma_s s) on the way,
//! energy-weighted means on arrival (Eq. 5-6); the path s one iteration stands for and the
//! diffusion correction are those of propagate.rs with h = the cell's radial length.
//!
//! What differs from the rectilinear grid:
//! - P is power (W), see init.rs; the fluence a cell sees is P s / V with V its volume.
//! - No side faces: the angular directions are closed (octahedral folding). Light leaves
//!   only through the outer shell.
//! - Outer faces are larger. A cubic lattice with equal front and back fractions keeps
//!   isotropic light where it is only if its density is uniform; here uniform fluence (the
//!   state a non-absorbing medium keeps) means power per cell proportional to V / s, which grows
//!   by q per shell when s is diffusion-matched (s ~ h^2 ~ r^2) and by q^2 when s = h. So the
//!   front and back fractions are weighted by R_out / r_mid and R_in / r_mid (squared when
//!   s = h) and the fractions renormalised: then uniform isotropic light is stationary, light
//!   drifts outwards as in physical diffusion about a point, and a lobe along the principal
//!   direction (all front) is unchanged. Departure from the paper, which does not say how it
//!   treats the isotropic part; without it diffuse light piles up towards the centre.
//! - `vacuum_escape` (on by default for radial grids, `PopSettings::radial_vacuum_escape`): in
//!   empty cells the isotropic part of the light leaves the grid, as in propagate.rs.
//! - Light sent inwards from the innermost shell crosses the centre and continues outwards in
//!   the opposite column; its lobe, about the old outward direction, is about the new one with
//!   anisotropy -a.

use glam::Vec3;
use rayon::prelude::*;

use super::grid::RadialGrid;
use super::init::RadialInitial;
use crate::error::{Error, Result};
use crate::phase::hg;
use crate::solvers::pop::propagate::{clamp_a, lobe_fractions, path_factor, per_channel, Emit};
use crate::solvers::pop::PropagationStats;
use crate::stages::Progress;


/// Per cell: cosine between the radial direction and the direction to the camera.
pub fn view_cosines(grid: &RadialGrid, camera: Vec3) -> Vec<f32> {
    let slab = grid.slab();
    (0..grid.len())
        .into_par_iter()
        .map(|c| {
            let d = grid.cols.directions[c % slab];
            d.dot((camera - grid.position(c)).normalize_or(d))
        })
        .collect()
}

/// Single scattering of the unscattered light: J += fluence f_hg(mu, a_direct g).
pub fn add_direct(init: &RadialInitial, mu: &[f32], g: f32, j_acc: &mut [Vec3]) {
    j_acc.par_iter_mut().enumerate().for_each(|(c, j)| {
        *j += init.direct[c] * hg(mu[c], clamp_a(init.a_direct[c] * g));
    });
}

pub struct RadialPropagation<'a> {
    pub grid: &'a RadialGrid,
    pub g: f32,
    pub mu: &'a [f32],
    pub diffusion_correction: bool,
    /// In empty cells the isotropic part of the light escapes (see `PopSettings::vacuum_escape`).
    pub vacuum_escape: bool,
    pub max_iterations: u32,
    pub residual_threshold: f32,
}

impl RadialPropagation<'_> {
    fn emit(&self, c: usize, a: Vec3) -> Emit {
        let grid = self.grid;
        let k = c / grid.slab();
        let h = grid.thickness(k);
        let (front, side, back) = lobe_fractions(a);
        // Outer faces are larger than inner ones (see the module doc): weights R_out / r_mid
        // and R_in / r_mid (squared without the diffusion correction), renormalised.
        let (r0, r1, rm) = (grid.radii[k], grid.radii[k + 1], grid.mid_radius(k));
        let m = if self.diffusion_correction { 1 } else { 2 };
        let (wf, wb) = ((r1 / rm).powi(m), (r0 / rm).powi(m));
        let z = front * wf + back * wb + side * 4.0;
        let inv = Vec3::select(z.cmpgt(Vec3::ZERO), Vec3::ONE / z.max(Vec3::splat(1e-30)), Vec3::ZERO);
        let (front, back, side) = (front * wf * inv, back * wb * inv, side * inv);
        let kappa = path_factor(self.diffusion_correction, front, back, a, grid.sigma_s[c], grid.sigma_a[c], self.g, h);
        Emit { front, side, back, path: kappa * h, a_front: a, a_side: a, a_back: a }
    }

    /// Runs the propagation from the injected packets (anisotropy a_direct g per cell); adds
    /// J = sum P (s / V) f_hg(mu, a g) into `j_acc`. Energy figures in W.
    pub fn run(&self, init: &RadialInitial, j_acc: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
        let grid = self.grid;
        let n = grid.len();
        let slab = grid.slab();
        let nk = grid.shells();
        let g = self.g;
        let ln_g = g.abs().max(1e-6).ln();
        let inv_volume: Vec<f32> = (0..nk).map(|k| 1.0 / grid.volume(k)).collect();
        let mut p = init.packets.clone();
        let mut a: Vec<Vec3> = init.a_direct.iter().map(|&a0| Vec3::splat(a0 * g)).collect();
        let mut p_next = vec![Vec3::ZERO; n];
        let mut a_next = vec![Vec3::ZERO; n];
        let mut emit = vec![Emit::default(); n];
        let injected: Vec3 = p.iter().copied().sum();
        let escaped_at = |c: usize, e: &Emit, pc: Vec3| if c / slab == nk - 1 { pc * e.front } else { Vec3::ZERO };
        // Iteration 0: packets born on average half a step from where they leave.
        let mut esc_next = emit
            .par_iter_mut()
            .zip(j_acc.par_iter_mut())
            .enumerate()
            .map(|(c, (e, jc))| {
                *e = self.emit(c, a[c]);
                let w = p[c] * e.path * (0.5 * inv_volume[c / slab]);
                *jc += w * per_channel(a[c], |ac| hg(self.mu[c], clamp_a(ac * g)));
                escaped_at(c, e, p[c])
            })
            .sum::<Vec3>();
        let (mut escaped, mut absorbed) = (Vec3::ZERO, Vec3::ZERO);
        let (mut remaining, mut before) = (injected, injected);
        let mut iterations = 0;
        let target = injected * self.residual_threshold;
        while iterations < self.max_iterations && remaining.cmpgt(target).any() && remaining.max_element() > 0.0 {
            iterations += 1;
            let (p_ref, a_ref, e_ref) = (&p, &a, &emit);
            p_next.par_chunks_mut(slab).zip(a_next.par_chunks_mut(slab)).enumerate().for_each(|(k, (pn, an))| {
                for col in 0..slab {
                    let dst = col + slab * k;
                    let (sa_d, ss_d) = (grid.sigma_a[dst], grid.sigma_s[dst]);
                    let mut l = Vec3::ZERO;
                    let mut la = Vec3::ZERO;
                    let mut add = |src: usize, frac: Vec3, sign: f32| {
                        let ps = p_ref[src];
                        if ps == Vec3::ZERO {
                            return;
                        }
                        let e = &e_ref[src];
                        let sa = 0.5 * (grid.sigma_a[src] + sa_d);
                        let ss = 0.5 * (grid.sigma_s[src] + ss_d);
                        let t = if sa == Vec3::ZERO { Vec3::ONE } else { (-sa * e.path).exp() };
                        let dl = ps * frac * t;
                        let da = if ss == Vec3::ZERO { a_ref[src] } else { a_ref[src] * (ss * e.path * ln_g).exp() };
                        l += dl;
                        la += dl * da * sign;
                    };
                    if k > 0 {
                        add(dst - slab, e_ref[dst - slab].front, 1.0);
                    } else {
                        // Through the centre from the opposite column.
                        let src = grid.cols.antipode[col] as usize;
                        add(src, e_ref[src].back, -1.0);
                    }
                    if k + 1 < nk {
                        add(dst + slab, e_ref[dst + slab].back, 1.0);
                    }
                    for &nb in &grid.cols.neighbours[col] {
                        let src = nb as usize + slab * k;
                        add(src, e_ref[src].side, 1.0);
                    }
                    pn[col] = l;
                    an[col] = Vec3::select(l.cmpgt(Vec3::splat(1e-30)), la / l.max(Vec3::splat(1e-30)), Vec3::ZERO);
                }
            });
            std::mem::swap(&mut p, &mut p_next);
            std::mem::swap(&mut a, &mut a_next);
            let a_ref = &a;
            let vacuum_escape = self.vacuum_escape;
            let (arrived, esc, vac) = emit
                .par_iter_mut()
                .zip(j_acc.par_iter_mut())
                .zip(p.par_iter_mut())
                .enumerate()
                .map(|(c, ((e, jc), pc))| {
                    let arrived = *pc;
                    if arrived == Vec3::ZERO {
                        *e = Emit::default();
                        return (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
                    }
                    let mut vac = Vec3::ZERO;
                    if vacuum_escape && grid.sigma_s[c] == Vec3::ZERO && grid.sigma_a[c] == Vec3::ZERO {
                        let keep = a_ref[c].abs().min(Vec3::ONE);
                        vac = *pc * (Vec3::ONE - keep);
                        *pc *= keep;
                    }
                    *e = self.emit(c, a_ref[c]);
                    let w = *pc * e.path * inv_volume[c / slab];
                    *jc += w * per_channel(a_ref[c], |ac| hg(self.mu[c], clamp_a(ac * g)));
                    (arrived, escaped_at(c, e, *pc), vac)
                })
                .reduce(|| (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO), |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2));
            absorbed += (before - esc_next - arrived).max(Vec3::ZERO);
            escaped += esc_next + vac;
            esc_next = esc;
            before = arrived - vac;
            remaining = arrived - vac;
            let decades = (remaining / injected.max(Vec3::splat(1e-30))).max_element().max(1e-12).log10();
            let frac = (iterations as f32 / self.max_iterations as f32).max(decades / self.residual_threshold.max(1e-12).log10());
            if !progress.update("pop radial propagation", frac.clamp(0.0, 1.0)) {
                return Err(Error::Cancelled);
            }
        }
        Ok(PropagationStats {
            iterations,
            injected: injected.to_array(),
            escaped: escaped.to_array(),
            absorbed: absorbed.to_array(),
            residual: remaining.to_array(),
            ..Default::default()
        })
    }
}
