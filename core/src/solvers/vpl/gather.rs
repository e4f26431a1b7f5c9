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
use std::sync::Arc;

use super::compensate::Compensation;
use super::settings::{NearField, VplSettings};
use super::walks::{Vpl, Walks};
use crate::rng::Rng;
use crate::scene::Scene;
use super::march::Marcher;
use crate::medium::{ball_mean_inverse_square, near_field_radius, Medium};
use crate::phase::hg;
use crate::solvers::pop::merge::{footprint, Merged};
use crate::solvers::pop::mip::MediumMip;
use crate::solvers::ScatteringGrid;
use crate::error::{Error, Result};
use crate::solvers::Progress;

/// Energy bookkeeping of the near field: the connections made, and the near field's energy
/// (sums over the gather points of sigma_s x J, channels added, per unit volume: comparable
/// with each other, not absolute).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct GatherStats {
    /// Connections made (point x VPL), the compensation's included.
    pub connections: u64,
    /// Connections shorter than the near-field radius.
    pub near: u64,
    /// What the gather points received from the VPLs with the near-field kernel in use.
    pub gathered: f64,
    /// What the clamp took away at the gather points (the ball kernel's value minus the
    /// clamped one, both from the same connections): zero with `near_field: ball`.
    pub clamped: f64,
    /// What the bias compensation put back (Sec. 4.3-4.4): zero without it.
    pub restored: f64,
    /// Compensation vertices sampled.
    pub vertices: u64,
}

impl GatherStats {
    pub fn add(&mut self, o: &GatherStats) {
        self.connections += o.connections;
        self.near += o.near;
        self.gathered += o.gathered;
        self.clamped += o.clamped;
        self.restored += o.restored;
        self.vertices += o.vertices;
    }
}

/// How 1/d^2 is kept finite near a VPL.
#[derive(Clone, Copy, Debug)]
pub enum Kernel {
    /// 1 / max(d, R)^2.
    Clamp(f32),
    /// The mean of 1/d^2 over a ball of this radius (medium::ball_mean_inverse_square).
    Ball(f32),
}

/// Light from `vpls` at `x`, scattered towards a viewer looking along `view` (the scattered
/// light propagates along -view), per unit sigma_s at `x`, with `kernel`; also what the clamp
/// lost there against the ball kernel of radius `ball` (zero for `Kernel::Ball`).
/// Transmittance to each VPL by a deterministic march of `step`.
#[allow(clippy::too_many_arguments)]
pub fn connect(march: &Marcher, vpls: &[Vpl], x: Vec3, view: Vec3, kernel: Kernel, ball: f32, step: f32, stats: &mut GatherStats) -> (Vec3, Vec3) {
    let g = march.medium().g;
    let (mut sum, mut lost) = (Vec3::ZERO, Vec3::ZERO);
    let radius = match kernel {
        Kernel::Clamp(r) | Kernel::Ball(r) => r,
    };
    for v in vpls {
        let to = x - v.position;
        let d = to.length();
        stats.connections += 1;
        if d < radius {
            stats.near += 1;
        }
        let w = to / d.max(1e-12);
        // At the VPL itself the direction is undefined: both lobes' mean, 1/4 pi.
        let (p_vpl, p_view) = if d > 1e-6 { (hg(v.incident.dot(w), g), hg(-w.dot(view), g)) } else { (0.25 * std::f32::consts::FRAC_1_PI, 0.25 * std::f32::consts::FRAC_1_PI) };
        let tr = if d > 1e-6 { (-march.optical_depth(v.position, w, d, step, 1024)).exp() } else { Vec3::ONE };
        let light = v.power * (p_vpl * p_view) * tr;
        match kernel {
            Kernel::Ball(r) => sum += light * ball_mean_inverse_square(d, r),
            Kernel::Clamp(r) => {
                let clamped = 1.0 / d.max(r).powi(2);
                sum += light * clamped;
                if d < r {
                    lost += light * (ball_mean_inverse_square(d, ball) - clamped).max(0.0);
                }
            }
        }
    }
    (sum, lost)
}

/// The subset of walks grid point (i, j, k) connects to.
#[inline]
fn subset_of(i: u32, j: u32, k: u32, subsets: u32) -> u32 {
    let m = (subsets as f32).cbrt().ceil().max(1.0) as u32;
    ((i % m) + m * (j % m) + m * m * (k % m)) % subsets
}

/// The VPLs of each of `subsets` interleaved sets of walks (walk w in set w mod subsets).
pub fn subset_lists(walks: &Walks, subsets: u32) -> Vec<Vec<Vpl>> {
    let mut lists = vec![Vec::new(); subsets as usize];
    for w in 0..walks.count() {
        lists[w % subsets as usize].extend_from_slice(walks.of_walk(w));
    }
    lists
}

/// The transmittance march's step for connections on a grid of this frame: its spacing, but
/// at most half a mean free path of the densest voxel, and at least one voxel. Why: a midpoint
/// march of steps several mean free paths long misses the dense parts between its samples (or
/// lands only on them), and exp() of such an optical depth is biased bright on average
/// (Jensen): on the white dense cloud (g 0.9), steps of the 10-cell gather grid's spacing (5
/// mean free paths) gave the compensated furnace S / sigma_s 1.29, a voxel step 1.0x (below).
pub fn march_step(medium: &Medium, frame: &glam::Affine3A) -> f32 {
    let m = frame.matrix3;
    let spacing = m.x_axis.length().min(m.y_axis.length()).min(m.z_axis.length());
    let sigma_max = medium.sigma_t(medium.grid.max_value()).max_element();
    let mfp_step = if sigma_max > 0.0 { 0.5 / sigma_max } else { spacing };
    spacing.min(mfp_step).max(medium.voxel_size_world().min_element())
}

/// What every gather point needs, built once per solve and shared by the backends
/// (backend.rs): the CPU connects point by point, the GPU all points at once, and both finish
/// each point the same way (`finish`: reweighting, energy report, compensation).
pub struct GatherPlan<'a> {
    medium: &'a Medium,
    mip: &'a MediumMip,
    camera: Vec3,
    /// The gather grid (J still zero).
    pub grid: ScatteringGrid,
    fp: f32,
    subsets: u32,
    /// The VPLs of each interleaved subset of walks.
    pub lists: Vec<Vec<Vpl>>,
    /// Near-field radius R.
    r: f32,
    /// Transmittance march step to the VPLs (`march_step`).
    pub step: f32,
    near_field: NearField,
    mean_free_paths: f32,
    seed: u64,
    compensation: Option<Compensation<'a>>,
    cell_volume: f64,
    /// The connections' transmittance march (march.rs), shared with the compensation.
    march: Arc<Marcher<'a>>,
}

/// One gather point's connection: where, seen from where, with which kernel, to which subset.
#[derive(Clone, Copy, Debug)]
pub struct GatherPoint {
    /// Index in the gather grid, i + nx (j + ny k).
    pub index: u32,
    pub position: Vec3,
    /// Direction from the camera to the point.
    pub view: Vec3,
    /// Mean density over the point's cell.
    pub rho: f32,
    pub kernel: Kernel,
    /// The ball kernel's radius there (what the clamp's loss is measured against).
    pub ball: f32,
    /// Its subset of walks (an index into `GatherPlan::lists`).
    pub subset: u32,
}

impl<'a> GatherPlan<'a> {
    pub fn new(scene: &'a Scene, mip: &'a MediumMip, walks: &Walks, s: &VplSettings) -> Result<Self> {
        let medium = &scene.medium;
        let grid = ScatteringGrid::over_medium(medium, s.gather_resolution)?;
        // Per-row radiance and density (16 bytes a point) and the merged density (4): the grid
        // itself was checked by `over_medium`.
        crate::budget::check_elements::<[f32; 5]>("vpl gather buffers (solver.gather_resolution)", grid.len() as u64)?;
        let fp = footprint(medium, &grid);
        let subsets = s.subsets();
        let r = s.clamp_radius * near_field_radius(&grid.index_to_world);
        let step = march_step(medium, &grid.index_to_world);
        let march = Arc::new(Marcher::new(medium));
        let compensation = (s.near_field == NearField::Compensate).then(|| Compensation::new(scene, mip, fp, walks, s, r, step, march.clone()));
        let cell_volume = glam::Mat3::from(grid.index_to_world.matrix3).determinant().abs() as f64;
        Ok(GatherPlan {
            medium,
            mip,
            camera: scene.camera.position,
            grid,
            fp,
            subsets,
            lists: subset_lists(walks, subsets),
            r,
            step,
            near_field: s.near_field,
            mean_free_paths: s.mean_free_paths,
            seed: s.seed,
            compensation,
            cell_volume,
            march,
        })
    }

    /// Grid point (i, j, k): its mean density, and its connection where there is density.
    pub fn point(&self, i: u32, jj: u32, k: u32) -> (f32, Option<GatherPoint>) {
        let medium = self.medium;
        let [nx, ny, _] = self.grid.dims;
        let y = self.grid.index_to_world.transform_point3(Vec3::new(i as f32, jj as f32, k as f32));
        let rho = self.mip.sample(medium, medium.world_to_index.transform_point3(y), self.fp);
        if rho <= 0.0 {
            return (rho, None);
        }
        let view = (y - self.camera).normalize_or(Vec3::Z);
        let ball = ball_radius(medium, rho, self.r, self.mean_free_paths);
        let kernel = match self.near_field {
            NearField::Ball => Kernel::Ball(ball),
            NearField::Clamp | NearField::Compensate => Kernel::Clamp(self.r),
        };
        let point = GatherPoint { index: i + nx * (jj + ny * k), position: y, view, rho, kernel, ball, subset: subset_of(i, jj, k, self.subsets) };
        (rho, Some(point))
    }

    /// J at a point from its connection's (sum, lost) (`connect`): the subset reweighted, the
    /// energy report, and the bias compensation when it is on.
    pub fn finish(&self, p: &GatherPoint, sum: Vec3, lost: Vec3, stats: &mut GatherStats) -> Vec3 {
        let back = self.compensation.as_ref().map(|c| c.estimate(p.position, -p.view, &mut self.compensation_rng(p), stats));
        self.finish_with(p, sum, lost, back, stats)
    }

    pub fn medium(&self) -> &'a Medium {
        self.medium
    }

    /// The connections' transmittance march.
    pub fn march(&self) -> &Marcher<'a> {
        &self.march
    }

    /// The compensation of `near_field: compensate`, if on.
    pub fn compensation(&self) -> Option<&Compensation<'a>> {
        self.compensation.as_ref()
    }

    /// The random numbers of a point's compensation (`Compensation::vertices`).
    pub fn compensation_rng(&self, p: &GatherPoint) -> Rng {
        Rng::new(self.seed ^ 0x5eed_c0de, p.index as u64)
    }

    /// `finish` with the compensation's estimate `back` already made (None: off).
    pub fn finish_with(&self, p: &GatherPoint, sum: Vec3, lost: Vec3, back: Option<Vec3>, stats: &mut GatherStats) -> Vec3 {
        let mut total = sum * self.subsets as f32;
        let sigma_s = self.medium.sigma_s(p.rho);
        let energy = |v: Vec3| (sigma_s * v).element_sum() as f64 * self.cell_volume;
        stats.gathered += energy(total);
        stats.clamped += energy(lost * self.subsets as f32);
        if let Some(back) = back {
            stats.restored += energy(back);
            total += back;
        }
        total
    }
}

/// J on the gather grid, with each point's mean density over its cell (the upsampling's guide).
/// Ends with `Error::Cancelled` within a row of gather points once `progress` is cancelled.
pub fn gather(scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<(Merged, GatherStats)> {
    let plan = GatherPlan::new(scene, mip, walks, s)?;
    let [nx, ny, nz] = plan.grid.dims;
    let rows: Vec<(Vec<Vec3>, Vec<f32>, GatherStats)> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut jv = vec![Vec3::ZERO; (nx * ny) as usize];
            let mut dens = vec![0.0f32; (nx * ny) as usize];
            let mut stats = GatherStats::default();
            'rows: for jj in 0..ny {
                for i in 0..nx {
                    // Per cell: a cell connects to thousands of VPLs (a row took 300 ms).
                    if progress.cancelled() {
                        break 'rows;
                    }
                    let idx = (i + nx * jj) as usize;
                    let (rho, point) = plan.point(i, jj, k);
                    dens[idx] = rho;
                    let Some(p) = point else { continue };
                    let (sum, lost) = connect(plan.march(), &plan.lists[p.subset as usize], p.position, p.view, p.kernel, p.ball, plan.step, &mut stats);
                    jv[idx] = plan.finish(&p, sum, lost, &mut stats);
                }
            }
            (jv, dens, stats)
        })
        .collect();
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    let mut j = plan.grid;
    let mut density = Vec::with_capacity(j.len());
    let mut stats = GatherStats::default();
    for (k, (jv, dens, st)) in rows.into_iter().enumerate() {
        let base = k * (nx * ny) as usize;
        j.data[base..base + jv.len()].copy_from_slice(&jv);
        density.extend(dens);
        stats.add(&st);
    }
    Ok((Merged { j, density }, stats))
}

/// Radius of the ball kernel at a point of density `rho`: `r`, at most `mean_free_paths` mean
/// free paths there (0: no such limit; see the setting).
pub fn ball_radius(medium: &Medium, rho: f32, r: f32, mean_free_paths: f32) -> f32 {
    let sigma_t = medium.sigma_t(rho.max(0.0)).max_element();
    if mean_free_paths > 0.0 && sigma_t > 0.0 { r.min(mean_free_paths / sigma_t) } else { r }
}
