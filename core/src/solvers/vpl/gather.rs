//! Gathering the VPLs on a coarse grid over the medium (paper 03 Sec. 4.2, 4.4a): at each
//! point y, J(y) = sum over the VPLs of its walk subset of
//!   subsets x power x p(incident -> w) x G(d) x T(x, y) x p(w -> towards the camera),
//! w the direction from the VPL to y; S = sigma_s J. J is per unit sigma_s so that the
//! density-guided upsampling can restore the density's detail (pop's upsample.rs).
//!
//! Interleaved sampling: the walks are cut into `subsets` interleaved sets (walk w in set
//! w mod subsets) and the points of each m x m x m block of the grid take one set each, the
//! result multiplied by the number of sets, so each point costs 1/subsets of the full gather
//! and the upsampling's filter averages the sets of neighbouring points.
//!
//! Transmittance: a deterministic ray march (medium::optical_depth) at the gather grid's
//! spacing (at least one voxel, as the compositor's shadow rays): noise-free, and finer detail
//! is lost in the coarse grid anyway.

use glam::Vec3;
use rayon::prelude::*;

use super::settings::{NearField, VplSettings};
use super::walks::{Vpl, Walks};
use crate::medium::{ball_mean_inverse_square, near_field_radius, optical_depth, Medium};
use crate::phase::hg;
use crate::solvers::pop::merge::{footprint, Merged};
use crate::solvers::pop::mip::MediumMip;
use crate::solvers::ScatteringGrid;
use crate::error::Result;

/// Energy bookkeeping of the near field (reported, for the clamp's loss).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct GatherStats {
    /// Connections made (point x VPL).
    pub connections: u64,
    /// Connections shorter than the near-field radius.
    pub near: u64,
}

/// The subset of walks grid point (i, j, k) connects to.
#[inline]
fn subset_of(i: u32, j: u32, k: u32, subsets: u32) -> u32 {
    let m = (subsets as f32).cbrt().ceil().max(1.0) as u32;
    ((i % m) + m * (j % m) + m * m * (k % m)) % subsets
}

/// The VPLs of each subset, concatenated.
fn subset_lists(walks: &Walks, subsets: u32) -> Vec<Vec<Vpl>> {
    let mut lists = vec![Vec::new(); subsets as usize];
    for w in 0..walks.count() {
        lists[w % subsets as usize].extend_from_slice(walks.of_walk(w));
    }
    lists
}

/// J on the gather grid, with each point's mean density over its cell (the upsampling's guide).
pub fn gather(medium: &Medium, mip: &MediumMip, camera: Vec3, walks: &Walks, s: &VplSettings) -> Result<(Merged, GatherStats)> {
    let mut j = ScatteringGrid::over_medium(medium, s.gather_resolution)?;
    let fp = footprint(medium, &j);
    let subsets = s.subsets();
    let lists = subset_lists(walks, subsets);
    let r = s.clamp_radius * near_field_radius(&j.index_to_world);
    let spacing = {
        let m = j.index_to_world.matrix3;
        m.x_axis.length().min(m.y_axis.length()).min(m.z_axis.length())
    };
    let step = spacing.max(medium.voxel_size_world().min_element());
    let g = medium.g;
    let frame = j.index_to_world;
    let [nx, ny, nz] = j.dims;
    let w2i = medium.world_to_index;
    let rows: Vec<(Vec<Vec3>, Vec<f32>, GatherStats)> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut jv = vec![Vec3::ZERO; (nx * ny) as usize];
            let mut dens = vec![0.0f32; (nx * ny) as usize];
            let mut stats = GatherStats::default();
            for jj in 0..ny {
                for i in 0..nx {
                    let y = frame.transform_point3(Vec3::new(i as f32, jj as f32, k as f32));
                    let rho = mip.sample(medium, w2i.transform_point3(y), fp);
                    let idx = (i + nx * jj) as usize;
                    dens[idx] = rho;
                    if rho <= 0.0 {
                        continue;
                    }
                    let view = (y - camera).normalize_or(Vec3::Z);
                    let sigma_t = medium.sigma_t(rho).max_element();
                    let r = if s.mean_free_paths > 0.0 && sigma_t > 0.0 { r.min(s.mean_free_paths / sigma_t) } else { r };
                    let mut sum = Vec3::ZERO;
                    for v in &lists[subset_of(i, jj, k, subsets) as usize] {
                        let to = y - v.position;
                        let d = to.length();
                        stats.connections += 1;
                        if d < r {
                            stats.near += 1;
                        }
                        let (geometry, w) = match s.near_field {
                            NearField::Clamp => (1.0 / d.max(r).powi(2), to / d.max(1e-12)),
                            NearField::Ball => (ball_mean_inverse_square(d, r), to / d.max(1e-12)),
                        };
                        // At the VPL itself the direction is undefined: both lobes' mean, 1/4 pi.
                        let (p_vpl, p_view) = if d > 1e-6 { (hg(v.incident.dot(w), g), hg(-w.dot(view), g)) } else { (0.25 * std::f32::consts::FRAC_1_PI, 0.25 * std::f32::consts::FRAC_1_PI) };
                        let tr = if d > 1e-6 { (-optical_depth(medium, v.position, w, d, step, 1024)).exp() } else { Vec3::ONE };
                        sum += v.power * (p_vpl * p_view * geometry) * tr;
                    }
                    jv[idx] = sum * subsets as f32;
                }
            }
            (jv, dens, stats)
        })
        .collect();
    let mut density = Vec::with_capacity(j.len());
    let mut stats = GatherStats::default();
    for (k, (jv, dens, st)) in rows.into_iter().enumerate() {
        let base = k * (nx * ny) as usize;
        j.data[base..base + jv.len()].copy_from_slice(&jv);
        density.extend(dens);
        stats.connections += st.connections;
        stats.near += st.near;
    }
    Ok((Merged { j, density }, stats))
}
