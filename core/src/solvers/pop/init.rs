//! Grid initialisation (Sec. 4.1): one sweep along the light through the depth slices,
//! accumulating optical depth per column.
//!
//! Departure from the paper. The paper fills the whole propagation grid with the attenuated
//! radiance L_in * T_i and then moves *all* of it one cell per iteration, adding every
//! iteration into the accumulation grid. Read literally that counts the unscattered beam once
//! per upstream cell (a cell at depth k would see k copies of it), which creates energy in
//! proportion to the grid resolution. Here the two parts of the light are kept apart, which is
//! what the radiative transfer equation does:
//! - the *unscattered* light is exact: fluence L_in * T(x) with T from the full extinction
//!   sigma_t, evaluated once (it is single scattering's source, with sharp shadows);
//! - what the beam loses to *scattering* in cell i, L_in * T_entry * (sigma_s / sigma_t) *
//!   (1 - exp(-sigma_t h)), is injected into the propagation grid as a packet with the
//!   anisotropy of once-scattered light, a = a0 * g (HG self-convolution), and only this
//!   energy is propagated by Eq. 1-6.
//!
//! Energy is then accounted for exactly: what enters a column either leaves it unscattered,
//! or is absorbed in the beam, or becomes a packet.

use glam::Vec3;
use rayon::prelude::*;

use super::light_grid::LightGrid;
use crate::error::{Error, Result};
use crate::stages::progress::{NoProgress, Progress};

#[derive(Clone)]
pub struct Initial {
    /// Fluence of the unscattered light at each cell centre (W/m^2).
    pub direct: Vec<Vec3>,
    /// Energy scattered out of the beam in each cell, in fluence units of one cell (W/m^2).
    pub packets: Vec<Vec3>,
    /// Sums over the columns that meet the medium, per cell cross-section (W/m^2 x cells):
    /// light entering, leaving unscattered, and absorbed before scattering.
    pub entering: Vec3,
    pub transmitted: Vec3,
    pub absorbed: Vec3,
}

/// `fluence`: fluence of the incident light (for a cone of half-angle theta with irradiance E
/// perpendicular to it: E * 2 / (1 + cos theta)).
pub fn sweep(grid: &LightGrid, fluence: Vec3) -> Initial {
    sweep_or_cancel(grid, fluence, &NoProgress).expect("NoProgress never cancels")
}

/// As `sweep`, stopping with `Error::Cancelled` once `progress` is cancelled (read per slice:
/// a fine grid's sweep takes a core tenths of a second).
pub fn sweep_or_cancel(grid: &LightGrid, fluence: Vec3, progress: &dyn Progress) -> Result<Initial> {
    let n = grid.len();
    let slab = grid.slab();
    let h = grid.h;
    let mut direct = vec![Vec3::ZERO; n];
    let mut packets = vec![Vec3::ZERO; n];
    let mut absorbed_col = vec![Vec3::ZERO; slab];
    // Optical depth from the entry face to the current slice, per column.
    let mut tau = vec![Vec3::ZERO; slab];
    for k in 0..grid.dims.z as usize {
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let range = k * slab..(k + 1) * slab;
        let (ss, sa) = (&grid.sigma_s[range.clone()], &grid.sigma_a[range.clone()]);
        direct[range.clone()]
            .par_iter_mut()
            .zip(packets[range].par_iter_mut())
            .zip(tau.par_iter_mut())
            .zip(absorbed_col.par_iter_mut())
            .enumerate()
            .for_each(|(c, (((dir, pk), t), ab))| {
                let st = ss[c] + sa[c];
                let t_entry = (-*t).exp();
                *dir = fluence * t_entry * (-st * (0.5 * h)).exp();
                let lost = fluence * t_entry * (Vec3::ONE - (-st * h).exp());
                // Fraction of the extinguished light that is scattered: sigma_s / sigma_t.
                let frac_s = Vec3::select(st.cmpgt(Vec3::splat(1e-12)), ss[c] / st.max(Vec3::splat(1e-12)), Vec3::ZERO);
                *pk = lost * frac_s;
                *ab += lost - *pk;
                *t += st * h;
            });
    }
    let mut entering = Vec3::ZERO;
    let mut transmitted = Vec3::ZERO;
    let mut absorbed = Vec3::ZERO;
    for (t, ab) in tau.iter().zip(&absorbed_col) {
        if t.max_element() > 0.0 {
            entering += fluence;
            transmitted += fluence * (-*t).exp();
            absorbed += *ab;
        }
    }
    Ok(Initial { direct, packets, entering, transmitted, absorbed })
}
