//! `near_refine`: the VPLs' light within a short distance of each output point, gathered at
//! the output point itself instead of being upsampled from the coarse grid.
//!
//! Why: the coarse gather and its upsampling give an output point x the J of its coarse
//! neighbours. Far from the VPLs J is smooth and that is right; but the light a point gets
//! from VPLs within a gather cell correlates with the density there -- the walks collide in
//! proportion to the density, so the VPLs sit in the same dense wisps as the points that
//! scatter most -- and S = sigma_s J averages to mean(sigma_s) mean(J) plus their covariance,
//! which a J sampled a cell away cannot carry. Measured: the local lights beside the plume
//! are 6-8% dark at a 12-16-cell gather and converge as the gather gets finer (tests.rs, above
//! `vpl_eight_seeds_flux_within_two_percent`).
//!
//! How (same expectation as the full gather at every output point, up to the upsampling of a
//! field that is smooth at the gather's scale): each VPL's contribution is split by a weight
//! phi(d) of its distance, 1 within half the radius r_n, falling linearly to 0 at r_n, into a
//! near part (phi) and a far part (1 - phi). The coarse gather (either backend) has J = far +
//! near at the coarse points; here the near part is gathered at the coarse points too (from
//! every walk, with the gather's kernel there) and upsampled with the same filter, and the
//! output becomes
//!   S(x) = [S_up(x) - S_near,up(x)]^+ + sigma_s(x) J_near(x),
//! J_near(x) gathered at x with the kernel of x's own density. The VPLs within r_n are found
//! through a hash grid of cell r_n. With `walks_per_subset` the coarse points used subsets
//! and the near part here every walk: the same expectation, not the same draw.
//!
//! Runs on the CPU for both backends (the GPU's gather and upsampling are equal to the CPU's,
//! so the two stay equal).

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use super::gather::{connect, kernel_for, march_step, GatherStats, Kernel};
use super::march::Marcher;
use super::settings::{NearField, VplSettings};
use super::walks::{Vpl, Walks};
use crate::error::{Error, Result};
use crate::medium::{near_field_radius, Medium};
use crate::scene::Scene;
use crate::stages::upsample::{footprint, Merged};
use crate::stages::mip::MediumMip;
use crate::stages::{Progress, ScatteringGrid};

/// The VPLs binned in cubes of side `cell` (world units), for the ones within `cell` of a point.
struct VplHash<'v> {
    vpls: &'v [Vpl],
    cell: f32,
    /// (cube key, VPL index), sorted by key.
    keys: Vec<(IVec3, u32)>,
}

impl<'v> VplHash<'v> {
    fn new(vpls: &'v [Vpl], cell: f32) -> Self {
        let mut keys: Vec<(IVec3, u32)> = vpls.iter().enumerate().map(|(i, v)| ((v.position / cell).floor().as_ivec3(), i as u32)).collect();
        keys.sort_unstable_by_key(|(k, i)| (k.z, k.y, k.x, *i));
        VplHash { vpls, cell, keys }
    }

    /// The VPLs within `cell` of `x` (and some a little further), into `out`, in a fixed order.
    fn near(&self, x: Vec3, out: &mut Vec<Vpl>) {
        out.clear();
        let c = (x / self.cell).floor().as_ivec3();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let k = c + IVec3::new(dx, dy, dz);
                    let key = (k.z, k.y, k.x);
                    let start = self.keys.partition_point(|(q, _)| (q.z, q.y, q.x) < key);
                    for (q, i) in &self.keys[start..] {
                        if *q != k {
                            break;
                        }
                        out.push(self.vpls[*i as usize]);
                    }
                }
            }
        }
    }
}

/// What the near part's gathers share (also vpl/near_ratio.rs's near part at the coarse points).
pub(super) struct Near<'a> {
    march: &'a Marcher<'a>,
    hash: VplHash<'a>,
    camera: Vec3,
    /// r_n (world units).
    radius: f32,
    /// The gather's near-field radius R and the ball kernel's mean-free-path limit.
    r: f32,
    mean_free_paths: f32,
    near_field: NearField,
    step: f32,
}

impl<'a> Near<'a> {
    /// The near part of the VPLs within `radius_cells` of the gather grid `frame`'s cells, with
    /// the kernel the gather uses (`settings`).
    pub(super) fn new(scene: &Scene, march: &'a Marcher<'a>, walks: &'a Walks, frame: &glam::Affine3A, radius_cells: f32, settings: &VplSettings) -> Self {
        let spacing = frame.matrix3.x_axis.length().max(frame.matrix3.y_axis.length()).max(frame.matrix3.z_axis.length());
        Near {
            march,
            hash: VplHash::new(&walks.vpls, radius_cells * spacing),
            camera: scene.camera.position,
            radius: radius_cells * spacing,
            r: settings.clamp_radius * near_field_radius(frame),
            mean_free_paths: settings.mean_free_paths,
            near_field: settings.near_field,
            step: march_step(march.medium(), frame),
        }
    }

    /// r_n (world units).
    pub(super) fn radius(&self) -> f32 {
        self.radius
    }

    /// The gather's kernel at a point of density `rho`, and the ball radius the clamp's loss is
    /// measured against.
    pub(super) fn kernel(&self, rho: f32) -> (Kernel, f32) {
        kernel_for(self.near_field, self.march.medium(), rho, self.r, self.mean_free_paths, 0.0)
    }

    /// J_near at `x` (density `rho` at the grid's footprint there): the VPLs within r_n,
    /// weighted by phi, with the kernel the gather uses at that density.
    pub(super) fn gather(&self, x: Vec3, rho: f32, list: &mut Vec<Vpl>, stats: &mut GatherStats) -> Vec3 {
        let (kernel, ball) = self.kernel(rho);
        let view = (x - self.camera).normalize_or(Vec3::Z);
        self.hash.near(x, list);
        let mut sum = Vec3::ZERO;
        for v in list.iter() {
            let phi = near_weight((x - v.position).length(), self.radius);
            if phi > 0.0 {
                sum += phi * connect(self.march, std::slice::from_ref(v), x, view, kernel, ball, self.step, stats).0;
            }
        }
        sum
    }

    /// J_near at the points of the gather grid `merged` where the gather ran (positive
    /// density; zero elsewhere). Ends with `Error::Cancelled` within a plane once `progress`
    /// is cancelled.
    pub(super) fn at_coarse(&self, merged: &Merged, progress: &dyn Progress) -> Result<ScatteringGrid> {
        let frame = merged.j.index_to_world;
        let [cx, cy, _] = merged.j.dims;
        let mut coarse = merged.j.clone();
        coarse.data.par_chunks_mut((cx * cy) as usize).enumerate().for_each(|(k, plane)| {
            let (mut list, mut stats) = (Vec::new(), GatherStats::default());
            for (o, j) in plane.iter_mut().enumerate() {
                if progress.cancelled() {
                    return;
                }
                let rho = merged.density[k * (cx * cy) as usize + o];
                *j = if rho > 0.0 {
                    let (i, jj) = (o as u32 % cx, o as u32 / cx);
                    self.gather(frame.transform_point3(Vec3::new(i as f32, jj as f32, k as f32)), rho, &mut list, &mut stats)
                } else {
                    Vec3::ZERO
                };
            }
        });
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        Ok(coarse)
    }
}

/// The share of a VPL at distance `d` that is near for r_n = `radius`: 1 within r_n / 2,
/// falling linearly to 0 at r_n.
#[inline]
pub(super) fn near_weight(d: f32, radius: f32) -> f32 {
    (2.0 - 2.0 * d / radius).clamp(0.0, 1.0)
}

/// Replaces the near part of `s` (S on the output grid, upsampled from `merged` by `upsample`)
/// by the near part gathered at the output points (module doc). Ends with `Error::Cancelled`
/// within a plane of output points once `progress` is cancelled.
#[allow(clippy::too_many_arguments)]
pub fn refine(
    scene: &Scene,
    mip: &MediumMip,
    walks: &Walks,
    merged: &Merged,
    s: &mut ScatteringGrid,
    settings: &VplSettings,
    progress: &dyn Progress,
    upsample: impl Fn(&Merged) -> Result<ScatteringGrid>,
) -> Result<()> {
    let medium: &Medium = &scene.medium;
    let frame = merged.j.index_to_world;
    let march = Marcher::new(medium);
    let near = Near::new(scene, &march, walks, &frame, settings.near_refine, settings);
    let coarse = near.at_coarse(merged, progress)?;
    let near_up = upsample(&Merged { j: coarse, density: merged.density.clone() })?;
    // At the output points: the upsampled near part out, the near part gathered there in.
    let [nx, ny, _] = s.dims;
    let (out_frame, fp) = (s.index_to_world, footprint(medium, s));
    let w2i = medium.world_to_index;
    s.data.par_chunks_mut((nx * ny) as usize).zip(near_up.data.par_chunks((nx * ny) as usize)).enumerate().for_each(|(k, (plane, up))| {
        let (mut list, mut stats) = (Vec::new(), GatherStats::default());
        for (o, (v, u)) in plane.iter_mut().zip(up).enumerate() {
            if progress.cancelled() {
                return;
            }
            let x = out_frame.transform_point3(Vec3::new((o as u32 % nx) as f32, (o as u32 / nx) as f32, k as f32));
            let rho = mip.sample(medium, w2i.transform_point3(x), fp);
            if rho <= 0.0 {
                continue;
            }
            *v = (*v - *u).max(Vec3::ZERO) + medium.sigma_s(rho) * near.gather(x, rho, &mut list, &mut stats);
        }
    });
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    Ok(())
}
