//! Lights into the propagation: what enters at the boundary (radiance per direction bin),
//! the emission as the initial U, and the first scattering computed exactly (U of the first
//! order from transmittance marched to every cell).
//!
//! - Dome: boundary radiance of bin i = the dome's mean radiance over the directions the bin's
//!   rays come from, by the bin's 4 x 4 sub-samples (the bin integral).
//! - Distant light, `first_order: boundary` (the paper): E / |Omega_i| in the bin of its
//!   direction. `exact` (default): U_d of the first order = sigma_s E T(x) mean_{w in d}
//!   p(w . w_sun), T marched to the cell through the grid, as POP's exact sweep.
//! - Point, spot, sphere and area lights (area: the compositor's 8 x 8 VPLs): first order
//!   exact the same way, inside the medium as well as outside (the brief's "inside: voxel
//!   emission" would smear a point light over a cell and lose its 1/d^2 shape; the exact
//!   first order keeps it, with 1/d^2 averaged over a cell-sized ball).
//! - Emission: the initial U, e(x) in every bin, propagated as an order of its own.
//!
//! The light scattered once is not collected into J: S's single scattering is the
//! compositor's exact grid (mod.rs), the same for every solver. Under the delta-M split
//! (delta_m.rs) J gets the light the phase function's peak scattered on along a beam, as the
//! true phase scatters it towards the viewer.

use glam::Vec3;
use rayon::prelude::*;

use super::delta_m::DeltaM;
use super::directions::Directions;
use super::grid::LpmGrid;
use super::phase_table::PhaseTable;
use super::settings::FirstOrder;
use crate::phase::hg;
use crate::scene::{Light, Scene};
use crate::stages::Progress;

/// Boundary radiance of each propagation direction for the first propagation.
pub fn boundary(scene: &Scene, dirs: &Directions, mode: FirstOrder) -> Vec<Vec3> {
    let mut out = vec![Vec3::ZERO; dirs.len()];
    for light in &scene.lights {
        match light {
            Light::Dome(env) => {
                for (i, b) in out.iter_mut().enumerate() {
                    // Rays travelling along w come from the sky at -w.
                    let sum: Vec3 = dirs.sub[i].iter().map(|&(w, o)| env.radiance(-w) * o).sum();
                    *b += sum / dirs.dirs[i].solid_angle;
                }
            }
            Light::Distant { direction, irradiance, .. } if mode == FirstOrder::Boundary => {
                let i = dirs.bin_of(direction.normalize());
                out[i] += *irradiance / dirs.dirs[i].solid_angle;
            }
            _ => {}
        }
    }
    out
}

/// Whether the first propagation has anything to carry: boundary radiance or emission.
pub fn first_propagation_needed(boundary: &[Vec3], scene: &Scene) -> bool {
    boundary.iter().any(|b| b.max_element() > 0.0) || scene.medium.emission.is_some()
}

/// The emission e(x) at each cell centre, in every storage bin of `u` (m values a cell).
pub fn emission_source(scene: &Scene, grid: &LpmGrid, m: usize, u: &mut [Vec3]) {
    let Some(em) = &scene.medium.emission else { return };
    let [nx, ny, _] = grid.dims;
    u.par_chunks_mut(nx * ny * m).enumerate().for_each(|(z, plane)| {
        for y in 0..ny {
            for x in 0..nx {
                let e = em.at(grid.centre([x, y, z]));
                let k = (x + nx * y) * m;
                plane[k..k + m].iter_mut().for_each(|v| *v += e);
            }
        }
    });
}

/// Adds the exact first scattering of the distant lights (in `exact` mode) and of the local
/// lights to U (m values a cell), split by `delta` (delta_m.rs: U gets the residual lobe's
/// share of the beam attenuated by sigma_t', J the peak-scattered light towards the viewer;
/// the identity split adds the true first scattering to U and nothing to J). `table` is the
/// propagated orders' (p'). Each cell traces a shadow ray per light (a second or more at
/// 128^3), so planes not started when the host cancels are skipped: the caller checks
/// `progress.cancelled()` and discards U.
#[allow(clippy::too_many_arguments)]
pub fn add_first_order(scene: &Scene, grid: &LpmGrid, dirs: &Directions, table: &PhaseTable, delta: &DeltaM, mode: FirstOrder, u: &mut [Vec3], j: &mut [Vec3], progress: &dyn Progress) {
    let medium = &scene.medium;
    let m = table.m;
    // Distant lights: travel direction, irradiance and the bins' mean phase towards it.
    let suns: Vec<(Vec3, Vec3, Vec<f32>)> = if mode == FirstOrder::Exact {
        scene
            .lights
            .iter()
            .filter_map(|l| match l {
                Light::Distant { direction, irradiance, .. } => {
                    let w = direction.normalize();
                    Some((w, *irradiance, (0..m).map(|d| PhaseTable::storage_mean_towards(dirs, d, w, table.lobe)).collect()))
                }
                _ => None,
            })
            .collect()
    } else {
        Vec::new()
    };
    // Far emitters merged past the tree's threshold (10,000 point lights: one shadow ray each
    // per cell was over 60 s).
    let emitters = crate::translate::EmitterTree::new(crate::translate::local_emitters(&scene.lights, crate::stages::single_scattering::AREA_VPLS_PER_SIDE));
    if suns.is_empty() && emitters.is_empty() {
        return;
    }
    let near = crate::medium::near_field_radius(&grid.frame());
    let camera = scene.camera.position;
    let [nx, ny, _] = grid.dims;
    // Light arriving along `w` with (true) transmittance `t` at p: its share of U (the residual
    // lobe, sigma_t' attenuation) and of J (the peak-scattered part towards the viewer).
    let add = |cell: &mut [Vec3], jv: &mut Vec3, p: Vec3, sigma: Vec3, w: Vec3, arriving: Vec3, t: Vec3, pbar: &dyn Fn(usize) -> f32| {
        let sigma_s = medium.albedo * sigma;
        let tp = delta.scaled_transmittance(t);
        // The cell's mean along the beam, not its centre's (`cell_mean_over_centre`).
        let (t, tp) = ((t * cell_mean_over_centre(sigma, grid.h, w)).min(Vec3::ONE), (tp * cell_mean_over_centre(sigma * delta.extinction, grid.h, w)).min(Vec3::ONE));
        let lit = sigma_s * (1.0 - delta.f) * arriving * tp;
        for (d, v) in cell.iter_mut().enumerate() {
            *v += lit * pbar(d);
        }
        if delta.active() {
            let to_cam = (camera - p).normalize_or(Vec3::Z);
            *jv += hg(w.dot(to_cam), delta.g) * arriving * (tp - t);
        }
    };
    u.par_chunks_mut(nx * ny * m).zip(j.par_chunks_mut(nx * ny)).enumerate().for_each(|(z, (plane, j_plane))| {
        if progress.cancelled() {
            return;
        }
        for y in 0..ny {
            for x in 0..nx {
                let c = [x, y, z];
                let idx = grid.index(c);
                let sigma = grid.sigma_t[idx];
                if (medium.albedo * sigma).max_element() <= 0.0 {
                    continue;
                }
                let p = grid.centre(c);
                let cell = &mut plane[(x + nx * y) * m..(x + nx * y + 1) * m];
                let jv = &mut j_plane[x + nx * y];
                for (w, e, pbar) in &suns {
                    add(cell, jv, p, sigma, *w, *e, grid.transmittance(p, -*w, f32::INFINITY), &|d| pbar[d]);
                }
                emitters.visit(p, |em| {
                    let to = em.position - p;
                    let dist = to.length();
                    if dist <= 1e-6 {
                        return;
                    }
                    let towards = to / dist;
                    let intensity = em.intensity_towards(-towards);
                    if intensity.max_element() <= 0.0 {
                        return;
                    }
                    // A cell's mean: at its centre a cell beside a sphere lamp would see the
                    // surface up close or not at all, as its centre falls.
                    let field = em.cell_mean_inverse_square(dist, near);
                    if field <= 0.0 {
                        return;
                    }
                    let arriving = intensity * field;
                    let bin = dirs.bin_of(-towards);
                    let t = if em.radius > near && dist < SPHERE_DISTANCE * em.radius {
                        // Near a sphere lamp its light crosses the medium along every direction
                        // it arrives from, not along the centre's alone (`sphere_directions`):
                        // their transmittances' mean, weighted by their shares.
                        let (mut sum, mut total) = (Vec3::ZERO, 0.0);
                        for (w, t, share) in em.sphere_directions(p, SPHERE_DIRECTIONS) {
                            sum += share * grid.transmittance(p, w, t);
                            total += share;
                        }
                        if total > 0.0 { sum / total } else { grid.transmittance(p, towards, em.shadow_length(dist)) }
                    } else {
                        grid.transmittance(p, towards, em.shadow_length(dist))
                    };
                    add(cell, jv, p, sigma, -towards, arriving, t, &|d| table.storage_mean_from_bin(dirs, d, bin));
                });
            }
        }
    });
}

/// Within this many radii of a sphere lamp the first order's transmittance is the mean over
/// the directions its light arrives from, `SPHERE_DIRECTIONS` of them (the compositor's
/// `near_lamps` sums the single scattering the same way there).
const SPHERE_DISTANCE: f32 = 4.0;
const SPHERE_DIRECTIONS: u32 = 16;

/// The mean over a cubic cell of side `h` of e^(-sigma (x - c) . w), x uniform in the cell: a
/// beam's transmittance averaged over the cell, over its value at the centre c, for sigma
/// constant in the cell. The offsets along the axes are independent, so it is the product of
/// sinh(a) / a, a = sigma h |w_i| / 2. Why: a cell of optical thickness 2 holds 17% more of the
/// beam than its centre's transmittance says, and the first order is the source of all the
/// others. Each a is capped at 20: past it the centre's transmittance has all but vanished.
fn cell_mean_over_centre(sigma: Vec3, h: f32, w: Vec3) -> Vec3 {
    let shc = |a: f32| -> f32 {
        let a = a.min(20.0);
        if a < 1e-2 { 1.0 + a * a / 6.0 } else { a.sinh() / a }
    };
    let per_channel = |s: f32| -> f32 { (0..3).map(|i| shc(0.5 * s * h * w[i].abs())).product() };
    Vec3::new(per_channel(sigma.x), per_channel(sigma.y), per_channel(sigma.z))
}
