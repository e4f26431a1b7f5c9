//! `normalize_energy`: the gathered multiple scattering scaled so that the power it scatters
//! equals the power the walks scattered, a departure from the paper (mod.rs).
//!
//! Why: every VPL but a walk's first marks a collision of light that had already scattered, so
//! the sum of their powers P is an unbiased estimate of the power the multiple scattering
//! scatters, integral over the medium of sigma_s phi_ms (phi_ms the fluence of light scattered
//! at least once), with the low variance of a sum over all VPLs. The gather estimates the same
//! integral as 4 pi sum sigma_s J_iso dV over the output grid, J_iso the gathered J with the
//! point's phase function replaced by 1 / 4 pi (gather.rs `connect_iso`), but it is biased
//! below a gather cell: the light of the VPLs within a cell correlates with the density there
//! (walks collide where the density is), which a coarse J times the fine sigma_s loses, and the
//! ball kernel moves a VPL's light within its radius onto thinner surroundings. So the
//! measured P / E corrects the whole grid: the share of the bias that is global. What it
//! cannot correct is where within the medium the light lands (the local lights' remaining
//! darkness, the dense cloud's directional heavy tail): settings.rs gives the numbers.
//!
//! Applied only where both sides are the same estimate: the gather's own near field (not
//! `compensate`, whose estimate has no isotropic twin), no `near_refine` or `near_upsample:
//! ratio` (they change the near part after the upsampling), and full walks (`max_orders`
//! would cut the collisions P counts).

use glam::Vec3;

use super::walks::Walks;
use crate::stages::ScatteringGrid;

/// The powers compared and the factor applied (W, RGB), reported by the solve.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct EnergyCheck {
    /// Power scattered at the walks' collisions after their first (the VPLs but each walk's
    /// first).
    pub walks: [f32; 3],
    /// The same power from the gathered, upsampled J_iso (4 pi sum of S_iso dV).
    pub gathered: [f32; 3],
    /// walks / gathered per channel (1 where either side is zero or not finite).
    pub factor: [f32; 3],
}

/// Power of the walks' collisions after their first (W, RGB), summed in f64.
pub fn walks_power(walks: &Walks) -> [f64; 3] {
    let mut p = [0.0f64; 3];
    for w in 0..walks.count() {
        for v in walks.of_walk(w).iter().skip(1) {
            for (c, x) in p.iter_mut().zip(v.power.to_array()) {
                *c += x as f64;
            }
        }
    }
    p
}

/// Power scattered by an in-scattering grid computed with an isotropic point phase
/// (S_iso = sigma_s J_iso): 4 pi times its sum times a cell's volume. The grid spans the
/// medium with a zero-density point at each end (ScatteringGrid::over_medium), so the plain
/// sum is the trapezoid rule of its trilinear reconstruction.
pub fn grid_power(s_iso: &ScatteringGrid) -> [f64; 3] {
    let cell = glam::Mat3::from(s_iso.index_to_world.matrix3).determinant().abs() as f64;
    let mut e = [0.0f64; 3];
    for v in &s_iso.data {
        for (c, x) in e.iter_mut().zip(v.to_array()) {
            *c += x as f64;
        }
    }
    e.map(|x| x * cell * 4.0 * std::f64::consts::PI)
}

/// Compares the two powers and scales `multiple` (the multiple scattering alone) by their
/// ratio per channel.
pub fn normalize(multiple: &mut ScatteringGrid, s_iso: &ScatteringGrid, walks: &Walks) -> EnergyCheck {
    let (p, e) = (walks_power(walks), grid_power(s_iso));
    let factor: [f32; 3] = std::array::from_fn(|c| {
        let f = p[c] / e[c];
        if p[c] > 0.0 && e[c] > 0.0 && f.is_finite() { f as f32 } else { 1.0 }
    });
    let f = Vec3::from(factor);
    if f != Vec3::ONE {
        for v in &mut multiple.data {
            *v *= f;
        }
    }
    EnergyCheck { walks: p.map(|x| x as f32), gathered: e.map(|x| x as f32), factor }
}
