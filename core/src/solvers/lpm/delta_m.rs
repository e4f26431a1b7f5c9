//! The delta-M split of the phase function (Wiscombe 1977; delta-Eddington, Joseph et al.
//! 1976) for the propagated orders. A g 0.9 Henyey-Greenstein lobe is ~6 degrees wide, a bin
//! of the 5 x 5 lattice ~16: the phase table averages the lobe over whole bins, so light
//! scattered forward leaks sideways into the neighbouring bins at every order and a g 0.9
//! medium comes out 1.2-1.9x too bright (tests.rs). The split writes
//! p(mu) = f delta(1 - mu) / 2 pi + (1 - f) p'(mu), with f = g^2 and p' the HG of
//! g' = (g - f) / (1 - f) = g / (1 + g) (its first moment keeps the true one). The peak is light
//! that goes on in its own direction, so the transfer equation of the scattered radiance
//! becomes the same equation with
//!   sigma_t' = sigma_t (1 - albedo f),  sigma_s' = sigma_s (1 - f),  phase p',
//! which the lattice represents well (g' 0.47 at g 0.9). Albedo and f are constants of the
//! medium, so sigma_t' is sigma_t times a per-channel constant: the scaled grid is the true one
//! scaled in place, and the GPU's kernels, which read sigma_t per cell, need no change.
//!
//! Where the split applies. Only S's single scattering keeps the true medium whole (the
//! compositor's exact grid, true sigma_t and p); everything lpm adds is split the same way:
//! - The unscattered light of the first order goes on through sigma_t': for suns and local
//!   lights (lights.rs) the beam's true transmittance T becomes T' = T^(1 - albedo f) per
//!   channel; for the first propagation (dome, emission, a boundary sun, mod.rs) the sweep runs
//!   through the scaled grid.
//! - U of the first order is what the residual lobe scatters out of that light:
//!   sigma_s' E T' p' for a beam, sigma_s' F' L0' for the first propagation.
//! - The light the peak scattered on (E (T' - T) along a beam) reaches the viewer by the true
//!   phase, into J: J += p(w_beam . w_view) E (T' - T); for the first propagation J gets the
//!   sweep's J through sigma_t' less the same sweep's J through the true sigma_t (that share
//!   is the compositor's single scattering).
//! - Orders two and up: propagated through sigma_t', collected into U with sigma_s' and p'.
//! - J towards the viewer from the propagated radiance: S = sigma_s integral p L, the true
//!   phase (the compositor marches S with the true sigma_t): `PhaseTable::view` is the true
//!   table.
//!
//! The split was measured against keeping the first order whole: docs/solvers/lpm.md.
//!
//! The residual need not be an HG lobe (`PeakSplit`). HG(g / (1 + g)) scatters half as much
//! again into the back hemisphere as the true HG(g) at g 0.9, so light turned back at a lit
//! face comes out too bright whatever the bins (docs/solvers/lpm.md, "The flattened peak").
//! `Flattened` cuts the true lobe off flat above a cosine `cap` (Lobe::flattened): f is the
//! share above the cap's value, and below it the residual is the true phase function. The cap
//! is fitted to the bins: where the transport's mean cosine through them, f + (1 - f) x the
//! table's, is g (phase_table::flattening_cap).

use glam::Vec3;

use super::directions::Directions;
use super::phase_table::{flattening_cap, Lobe, PhaseTable};
use super::settings::PeakSplit;
use crate::error::Result;

/// The split of one medium: peak fraction, residual anisotropy and the per-channel scales.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeltaM {
    /// Forward-peak fraction f (0: the split is off).
    pub f: f32,
    /// The medium's g.
    pub g: f32,
    /// The residual HG lobe's g' = (g - f) / (1 - f) (g itself when the peak is flattened:
    /// the residual is then the true lobe, `cap`).
    pub g_scaled: f32,
    /// sigma_t' / sigma_t = 1 - albedo f.
    pub extinction: Vec3,
    /// The scaled albedo sigma_s' / sigma_t' = albedo (1 - f) / (1 - albedo f).
    pub albedo: Vec3,
    /// The cosine above which the true lobe is flattened (`PeakSplit::Flattened`); `None`:
    /// the residual is the HG of `g_scaled`.
    pub cap: Option<f32>,
}

impl DeltaM {
    /// f = g^2 where `on` and g > 0 (a backward lobe has no forward peak to split off),
    /// else the identity split (f = 0: every scale is exactly 1, the solve unchanged).
    pub fn new(on: bool, g: f32, albedo: Vec3) -> Self {
        let f = if on && g > 0.0 { g * g } else { 0.0 };
        let g_scaled = if f > 0.0 { (g - f) / (1.0 - f) } else { g };
        Self::with_peak(f, g, g_scaled, albedo, None)
    }

    /// The split `split` for the propagation bins `dirs`. Flattened: the cap is where the
    /// propagation, through the bins, carries light on with the mean cosine g
    /// (`phase_table::flattening_cap`); f is the share above the cap's value.
    pub fn for_bins(on: bool, split: PeakSplit, g: f32, albedo: Vec3, dirs: &Directions) -> Result<Self> {
        if !(on && g > 0.0 && split == PeakSplit::Flattened) {
            return Ok(Self::new(on, g, albedo));
        }
        let cap = flattening_cap(dirs, g)?;
        Ok(Self::with_peak(Lobe::flattened(g, cap).peak(), g, g, albedo, Some(cap)))
    }

    /// The scales of a split whose peak holds the fraction `f` of the scattered light.
    fn with_peak(f: f32, g: f32, g_scaled: f32, albedo: Vec3, cap: Option<f32>) -> Self {
        let extinction = Vec3::ONE - albedo * f;
        // albedo f < 1 whenever g < 1 (the medium's range): no division by zero.
        let scaled_albedo = if f > 0.0 { albedo * (1.0 - f) / extinction } else { albedo };
        DeltaM { f, g, g_scaled, extinction, albedo: scaled_albedo, cap }
    }

    pub fn active(&self) -> bool {
        self.f > 0.0
    }

    /// The propagated orders' phase table: fine and storage rows from p', the view rows
    /// (J towards the camera) from the true table `truth`.
    pub fn table(&self, dirs: &Directions, truth: &PhaseTable) -> Result<PhaseTable> {
        // A flattened split keeps the cap fitted to the solve's bins on any others (the late
        // orders' coarse ones, coarse.rs): f, and so sigma_t', is one for the whole solve.
        if let Some(cap) = self.cap {
            return Ok(PhaseTable::from_lobe(dirs, Lobe::flattened(self.g, cap))?.with_view(truth.view_table().into_owned()));
        }
        Ok(PhaseTable::keeping_mean_cosine(dirs, self.g_scaled)?.with_view(truth.view_table().into_owned()))
    }

    /// Transmittance along the beam through sigma_t' from the true transmittance `t`
    /// (optical depth scaled per channel).
    #[inline]
    pub fn scaled_transmittance(&self, t: Vec3) -> Vec3 {
        if !self.active() {
            return t;
        }
        Vec3::new(t.x.powf(self.extinction.x), t.y.powf(self.extinction.y), t.z.powf(self.extinction.z))
    }

    /// Scales the extinction of `sigma_t` (the propagation grid's cells) in place.
    pub fn scale_extinction(&self, sigma_t: &mut [Vec3]) {
        if self.active() {
            sigma_t.iter_mut().for_each(|s| *s *= self.extinction);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phase::hg;

    /// The split keeps what the transfer equation needs: the absorption sigma_t' - sigma_s' =
    /// sigma_t - sigma_s (the peak neither absorbs nor scatters sideways), the residual lobe's
    /// first moment times (1 - f) plus the peak's f equals g (so the transport's mean cosine is
    /// kept), and at g 0.9 the residual is the broad lobe the lattice can carry (g' = 0.474).
    /// Off, or g <= 0, every scale is exactly 1.
    #[test]
    fn delta_m_keeps_absorption_and_first_moment() {
        let albedo = Vec3::new(0.99, 0.8, 0.5);
        let d = DeltaM::new(true, 0.9, albedo);
        let sigma_t = 3.0f32;
        let (st, ss) = (sigma_t * d.extinction, sigma_t * d.extinction * d.albedo);
        let absorption = st - ss;
        let want = sigma_t * (Vec3::ONE - albedo);
        assert!((absorption - want).abs().max_element() < 1e-5, "{absorption:?} vs {want:?}");
        assert!((ss - sigma_t * albedo * (1.0 - d.f)).abs().max_element() < 1e-5);
        // First moment of p' by a 20000-step midpoint rule over mu (2 pi integral p' mu dmu).
        let n = 20_000;
        let m1: f64 = (0..n)
            .map(|i| {
                let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                2.0 * std::f64::consts::PI * hg(mu as f32, d.g_scaled) as f64 * mu * 2.0 / n as f64
            })
            .sum();
        let total = d.f as f64 + (1.0 - d.f as f64) * m1;
        assert!((total - 0.9).abs() < 1e-3, "moment {total}");
        assert!((d.g_scaled - 0.9 / 1.9).abs() < 1e-6, "{}", d.g_scaled);
        for off in [DeltaM::new(false, 0.9, albedo), DeltaM::new(true, -0.3, albedo), DeltaM::new(true, 0.0, albedo)] {
            assert!(!off.active());
            assert_eq!(off.extinction, Vec3::ONE);
            assert_eq!(off.albedo, albedo);
            assert_eq!(off.scaled_transmittance(Vec3::splat(0.3)), Vec3::splat(0.3));
        }
        // T' = exp(-tau (1 - albedo f)) from T = exp(-tau).
        let tau = 2.5f32;
        let tp = d.scaled_transmittance(Vec3::splat((-tau).exp()));
        let want = (-tau * d.extinction).exp();
        assert!((tp - want).abs().max_element() < 1e-6, "{tp:?} vs {want:?}");
    }
}
