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
//! is lost in the coarse grid anyway. With `transmittance: map` (the default) only for the
//! VPLs within `MAP_EXACT_CELLS`; the farther ones read a per-point map (depth_map.rs).

use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

use super::compensate::Compensation;
use super::settings::{NearField, Transmittance, VplSettings};
use super::walks::{Vpl, Walks};
use crate::rng::Rng;
use crate::scene::Scene;
use super::depth_map::DepthMap;
use super::far_field::{Cluster, FarField};
use super::march::Marcher;
use crate::medium::{ball_mean_inverse_square, min_spacing, near_field_radius, Medium};
use crate::stages::single_scattering::{exp_neg, is_grey};
use crate::phase::hg;
use crate::stages::upsample::{footprint, Merged};
use crate::stages::mip::MediumMip;
use crate::stages::ScatteringGrid;
use crate::error::{Error, Result};
use crate::stages::Progress;

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

/// What a backend's gather returns (backend.rs).
pub struct Gathered {
    /// J on the gather grid with its density guide.
    pub merged: Merged,
    pub stats: GatherStats,
    /// J_iso at the gather grid's points (`connect_iso`, the subset reweighted; zero where there
    /// is no density): what `normalize_energy` integrates (energy.rs).
    pub iso: Vec<Vec3>,
}

/// How 1/d^2 is kept finite near a VPL.
#[derive(Clone, Copy, Debug)]
pub enum Kernel {
    /// 1 / max(d, R)^2.
    Clamp(f32),
    /// The mean of 1/d^2 over a ball of radius `radius` around the VPL
    /// (medium::ball_mean_inverse_square): the VPL's light spread over the ball. With `cone` > 0
    /// both phase functions are smoothed as if the VPL were spread over a ball of radius `cone`:
    /// HG with g times the mean cosine of the cone that ball subtends (`cone_mean_cosine`;
    /// isotropic inside it). Mean cosines multiply under such a convolution, so the lobes keep
    /// their integral (the energy) and only lose the peaks that, times the ball's 3 / r^2, make
    /// the dense cloud's heavy tail (settings.rs `phase_cone`).
    Ball { radius: f32, cone: f32 },
    /// The attenuated top hat: a VPL within `radius` gives `inside` (per channel, no
    /// transmittance), one beyond gives T / d^2. `inside` = 3 (1 - e^{-sigma R}) / (sigma R^3)
    /// is the mean over the ball of the homogeneous kernel e^{-sigma d} / d^2, sigma the
    /// extinction at the gather point (`hat_inside`), so the kernel's integral over space is
    /// that of T / d^2 in a medium of that extinction: lossless however many mean free paths
    /// the ball spans. Inside, the two phase functions are replaced by their mean over the
    /// ball's directions, HG of g^2 from the VPL's incident direction to the viewer (the
    /// uniform density the hat assumes makes every direction from the VPL to the point equally
    /// likely); beyond, they are smoothed over the cone of a ball of radius `cone`, as `Ball`'s.
    Hat { radius: f32, cone: f32, inside: Vec3 },
}

/// The top hat's value inside its ball of radius r for extinction sigma (per channel):
/// 3 (1 - e^{-sigma r}) / (sigma r^3), 3 / r^2 where sigma r vanishes.
pub fn hat_inside(sigma: Vec3, r: f32) -> Vec3 {
    let f = |s: f32| {
        let x = s * r;
        if x < 1e-4 { 3.0 / (r * r) * (1.0 - 0.5 * x) } else { -3.0 * (-x).exp_m1() / (x * r * r) }
    };
    Vec3::new(f(sigma.x), f(sigma.y), f(sigma.z))
}

impl Kernel {
    /// R of the clamp or the ball's radius.
    pub fn radius(self) -> f32 {
        match self {
            Kernel::Clamp(r) | Kernel::Ball { radius: r, .. } | Kernel::Hat { radius: r, .. } => r,
        }
    }
}

/// Light from `vpls` at `x`, scattered towards a viewer looking along `view` (the scattered
/// light propagates along -view), per unit sigma_s at `x`, with `kernel`; also what the clamp
/// lost there against the ball kernel of radius `ball` (zero for `Kernel::Ball`).
/// Transmittance to each VPL by a deterministic march of `step`.
#[allow(clippy::too_many_arguments)]
pub fn connect(march: &Marcher, vpls: &[Vpl], x: Vec3, view: Vec3, kernel: Kernel, ball: f32, step: f32, stats: &mut GatherStats) -> (Vec3, Vec3) {
    let (sum, lost, _) = connect_iso(march, vpls, x, view, kernel, ball, step, stats);
    (sum, lost)
}

/// `connect`, and the same light with the point's phase function replaced by 1 / 4 pi (J_iso,
/// the fluence over 4 pi per unit sigma_s): what `normalize_energy` integrates (energy.rs).
#[allow(clippy::too_many_arguments)]
pub fn connect_iso(march: &Marcher, vpls: &[Vpl], x: Vec3, view: Vec3, kernel: Kernel, ball: f32, step: f32, stats: &mut GatherStats) -> (Vec3, Vec3, Vec3) {
    connect_with(march.medium(), vpls, x, view, kernel, ball, stats, |from: Vec3, w: Vec3, d: f32| march.optical_depth(from, w, d, step, MAX_STEPS))
}

/// Most steps of a connection's transmittance march.
const MAX_STEPS: u32 = 1024;

/// `connect_iso` with the transmittance of `map` (`transmittance: map`, depth_map.rs) for the
/// VPLs at least `exact` away from `x`, the march of `step` for the nearer ones.
#[allow(clippy::too_many_arguments)]
pub fn connect_iso_mapped(march: &Marcher, map: &DepthMap, exact: f32, vpls: &[Vpl], x: Vec3, view: Vec3, kernel: Kernel, ball: f32, step: f32, stats: &mut GatherStats) -> (Vec3, Vec3, Vec3) {
    connect_with(march.medium(), vpls, x, view, kernel, ball, stats, mapped_depth(march, map, exact, step))
}

/// The optical depth from a point `from` along unit w over d to the map's point: the map's
/// beyond `exact`, marched with `step` nearer.
#[inline(always)]
fn mapped_depth<'m>(march: &'m Marcher, map: &'m DepthMap, exact: f32, step: f32) -> impl Fn(Vec3, Vec3, f32) -> Vec3 + 'm {
    let scale = march.medium().density_scale;
    move |from: Vec3, w: Vec3, d: f32| {
        if d < exact {
            march.optical_depth(from, w, d, step, MAX_STEPS)
        } else {
            // The map looks from x towards the VPL.
            scale * map.lookup(-w, d)
        }
    }
}

/// The light of far VPL clusters (far_field.rs) at `x`, as `connect_iso` gives a VPL's: each
/// cluster one connection from its centroid, its VPLs' lobes as |m| whole lobes about their mean
/// incident direction and the rest isotropic, 1/d^2 with its mean over the cluster's spread (the module
/// doc of far_field.rs). Clusters are never within the near-field radius (they are at least
/// `cluster_distance` cells away), so nothing is clamped: (sum, iso).
#[inline(always)]
fn connect_clusters(medium: &Medium, clusters: &[Cluster], x: Vec3, view: Vec3, kernel: Kernel, stats: &mut GatherStats, depth: impl Fn(Vec3, Vec3, f32) -> Vec3) -> (Vec3, Vec3) {
    let grey = is_grey(medium);
    const ISO: f32 = 0.25 * std::f32::consts::FRAC_1_PI;
    let (mut sum, mut iso) = (Vec3::ZERO, Vec3::ZERO);
    stats.connections += clusters.len() as u64;
    for c in clusters {
        let to = x - c.centroid;
        let d = to.length().max(1e-6);
        let w = to / d;
        let g = match kernel {
            Kernel::Ball { cone, .. } | Kernel::Hat { cone, .. } if cone > 0.0 => medium.g * cone_mean_cosine(d, cone),
            _ => medium.g,
        };
        // The directions from the cluster's VPLs to x spread about w: both lobes convolved
        // with that spread, whose mean cosine is 1 - s^2 / (3 d^2) to second order (lateral
        // variance 2 s^2 / 3 over d^2), so HG with g times it (as `cone_mean_cosine`).
        let widening = (1.0 - c.spread / (3.0 * d * d)).max(0.0);
        let g = g * widening;
        // The VPLs' lobes: a share |m| of whole lobes about the mean incident direction, the
        // rest isotropic (far_field.rs).
        let m = c.mean_incident.length();
        let p_vpl = if m > 1e-6 { m * hg(c.mean_incident.dot(w) / m, g) + (1.0 - m) * ISO } else { ISO };
        let p_view = hg(-w.dot(view), g);
        // The mean over the spread along the line (far_field.rs): e^-tau's convexity and the
        // nearer VPLs' being both closer and less attenuated, to second order.
        let v = c.spread / 3.0;
        let tr = exp_neg(depth(c.centroid, w, d), grey) * (Vec3::ONE + c.extinction * c.extinction * (0.5 * v) + c.extinction * (2.0 * v / d));
        let b = match kernel {
            Kernel::Ball { radius, .. } => ball_mean_inverse_square(d, radius),
            Kernel::Clamp(r) => 1.0 / d.max(r).powi(2),
            Kernel::Hat { .. } => 1.0 / (d * d),
        } * (1.0 + c.spread / (3.0 * d * d));
        let light = c.power * (p_vpl * b) * tr;
        sum += light * p_view;
        iso += light * ISO;
    }
    (sum, iso)
}

/// `connect_iso` with the optical depth (RGB) from each VPL along unit w over d from `depth`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn connect_with(medium: &Medium, vpls: &[Vpl], x: Vec3, view: Vec3, kernel: Kernel, ball: f32, stats: &mut GatherStats, depth: impl Fn(Vec3, Vec3, f32) -> Vec3) -> (Vec3, Vec3, Vec3) {
    let g = medium.g;
    let grey = is_grey(medium);
    let (mut sum, mut lost, mut iso) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    const ISO: f32 = 0.25 * std::f32::consts::FRAC_1_PI;
    let radius = kernel.radius();
    for v in vpls {
        let to = x - v.position;
        let d = to.length();
        stats.connections += 1;
        if d < radius {
            stats.near += 1;
        }
        // Inside the top hat's ball: its constant, the lobes' mean over the ball's directions,
        // no transmittance (the kernel doc).
        if let Kernel::Hat { inside, .. } = kernel {
            if d < radius {
                let pg = hg(-v.incident.dot(view), g * g);
                sum += v.power * (ISO * pg) * inside;
                iso += v.power * (ISO * ISO) * inside;
                continue;
            }
        }
        let w = to / d.max(1e-12);
        // The ball kernel's phases smoothed over the cone of its `cone` ball (kernel doc).
        let g = match kernel {
            Kernel::Ball { cone, .. } | Kernel::Hat { cone, .. } if cone > 0.0 => g * cone_mean_cosine(d, cone),
            _ => g,
        };
        // At the VPL itself the direction is undefined: both lobes' mean, 1/4 pi.
        let (p_vpl, p_view) = if d > 1e-6 { (hg(v.incident.dot(w), g), hg(-w.dot(view), g)) } else { (0.25 * std::f32::consts::FRAC_1_PI, 0.25 * std::f32::consts::FRAC_1_PI) };
        // One exp where the channels' extinction is the same (the same values).
        let tr = if d > 1e-6 { exp_neg(depth(v.position, w, d), grey) } else { Vec3::ONE };
        let light = v.power * (p_vpl * p_view) * tr;
        let light_iso = v.power * (p_vpl * ISO) * tr;
        match kernel {
            Kernel::Hat { .. } => {
                let b = 1.0 / (d * d);
                sum += light * b;
                iso += light_iso * b;
            }
            Kernel::Ball { radius: r, .. } => {
                let b = ball_mean_inverse_square(d, r);
                sum += light * b;
                iso += light_iso * b;
            }
            Kernel::Clamp(r) => {
                let clamped = 1.0 / d.max(r).powi(2);
                sum += light * clamped;
                iso += light_iso * clamped;
                if d < r {
                    lost += light * (ball_mean_inverse_square(d, ball) - clamped).max(0.0);
                }
            }
        }
    }
    (sum, lost, iso)
}

/// Mean cosine of the directions from a point to a ball of radius r at distance d, uniform over
/// the solid angle of the cone it subtends ((1 + cos a) / 2, sin a = r / d; 0 inside the ball,
/// where the directions cover the sphere). Uniform over the cone is a little wider than the
/// ball's own chord-weighted spread: the smoothing errs towards the smooth side.
pub fn cone_mean_cosine(d: f32, r: f32) -> f32 {
    if d <= r {
        return 0.0;
    }
    let s = r / d;
    0.5 * (1.0 + (1.0 - s * s).max(0.0).sqrt())
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
    let spacing = min_spacing(frame);
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
    /// Largest radius of the ball kernel's phase smoothing (`phase_cone` gather-cell radii).
    cone: f32,
    near_field: NearField,
    mean_free_paths: f32,
    seed: u64,
    compensation: Option<Compensation<'a>>,
    cell_volume: f64,
    /// The connections' transmittance march (march.rs), shared with the compensation.
    march: Arc<Marcher<'a>>,
    /// `transmittance: map`: the depth map's side (0: march every connection) and the
    /// distance below which connections are still marched (`MAP_EXACT_CELLS`).
    pub map_resolution: u32,
    pub map_exact: f32,
    /// `cluster_distance` > 0: the far-field tree of each subset's VPLs (far_field.rs); empty:
    /// every VPL connected one by one.
    pub far: Vec<FarField>,
}

/// A gather thread's scratch space, reused from point to point.
#[derive(Default)]
pub struct Scratch {
    map: Option<DepthMap>,
    stack: Vec<(u32, glam::UVec3)>,
    clusters: Vec<Cluster>,
}

/// `transmittance: map`: connections shorter than this many gather-grid spacings are marched,
/// not looked up (depth_map.rs: the near VPLs carry most of J, and their march is short); one
/// cell was the fastest at the same error (docs/solvers/vpl.md).
pub const MAP_EXACT_CELLS: f32 = 1.0;

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
        let cone = s.phase_cone * near_field_radius(&grid.index_to_world);
        let map_exact = MAP_EXACT_CELLS * min_spacing(&grid.index_to_world);
        let step = march_step(medium, &grid.index_to_world);
        let march = Arc::new(Marcher::new(medium));
        let compensation = (s.near_field == NearField::Compensate).then(|| Compensation::new(scene, mip, fp, walks, s, r, step, march.clone()));
        let cell_volume = glam::Mat3::from(grid.index_to_world.matrix3).determinant().abs() as f64;
        let lists = subset_lists(walks, subsets);
        let far = if s.cluster_distance > 0.0 { lists.iter().map(|l| FarField::new(l, grid.dims, &grid.index_to_world, s.cluster_distance, Some(medium))).collect::<Result<Vec<_>>>()? } else { Vec::new() };
        Ok(GatherPlan {
            medium,
            mip,
            camera: scene.camera.position,
            grid,
            fp,
            subsets,
            lists,
            r,
            step,
            cone,
            near_field: s.near_field,
            mean_free_paths: s.mean_free_paths,
            seed: s.seed,
            compensation,
            cell_volume,
            march,
            map_resolution: if s.transmittance == Transmittance::Map { s.map_resolution } else { 0 },
            map_exact,
            far,
        })
    }

    /// Scratch space for `connect_point` (one per thread).
    pub fn scratch(&self) -> Scratch {
        Scratch { map: (self.map_resolution > 0).then(|| DepthMap::new(self.map_resolution)), ..Default::default() }
    }

    /// A point's (sum, lost, iso) over its subset of walks (`connect_iso`): with the depth map
    /// where `transmittance: map`, with the far VPLs as clusters where `cluster_distance` > 0.
    pub fn connect_point(&self, p: &GatherPoint, scratch: &mut Scratch, stats: &mut GatherStats) -> (Vec3, Vec3, Vec3) {
        let march = self.march();
        let (x, view, kernel, ball) = (p.position, p.view, p.kernel, p.ball);
        if let Some(map) = scratch.map.as_mut() {
            map.build(march, x, self.step, MAX_STEPS);
        }
        let Scratch { map, stack, clusters } = scratch;
        let map = map.as_ref();
        // VPLs one by one: looked up in the map (where on) or marched.
        let one_by_one = |vpls: &[Vpl], stats: &mut GatherStats| match map {
            Some(map) => connect_iso_mapped(march, map, self.map_exact, vpls, x, view, kernel, ball, self.step, stats),
            None => connect_iso(march, vpls, x, view, kernel, ball, self.step, stats),
        };
        let Some(tree) = self.far.get(p.subset as usize) else {
            return one_by_one(&self.lists[p.subset as usize], stats);
        };
        let (mut sum, mut lost, mut iso) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        clusters.clear();
        tree.visit(x, stack, |vpls| {
            let (s, l, i) = one_by_one(vpls, stats);
            sum += s;
            lost += l;
            iso += i;
        }, |c| clusters.push(*c));
        let (s, i) = match map {
            Some(map) => connect_clusters(self.medium, clusters, x, view, kernel, stats, mapped_depth(march, map, self.map_exact, self.step)),
            None => connect_clusters(self.medium, clusters, x, view, kernel, stats, |from: Vec3, w: Vec3, d: f32| march.optical_depth(from, w, d, self.step, MAX_STEPS)),
        };
        (sum + s, lost, iso + i)
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
        let (kernel, ball) = kernel_for(self.near_field, medium, rho, self.r, self.mean_free_paths, self.cone);
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

    /// A point's sum over its subset of walks as an estimate over all walks.
    pub fn reweight(&self, sum: Vec3) -> Vec3 {
        sum * self.subsets as f32
    }

    /// `finish` with the compensation's estimate `back` already made (None: off).
    pub fn finish_with(&self, p: &GatherPoint, sum: Vec3, lost: Vec3, back: Option<Vec3>, stats: &mut GatherStats) -> Vec3 {
        let mut total = self.reweight(sum);
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

/// One plane (fixed k) of the gather grid: J, J_iso and the density guide, row-major.
struct Plane {
    j: Vec<Vec3>,
    iso: Vec<Vec3>,
    density: Vec<f32>,
    stats: GatherStats,
}

/// J on the gather grid, with each point's mean density over its cell (the upsampling's guide).
/// Ends with `Error::Cancelled` within a row of gather points once `progress` is cancelled.
pub fn gather(scene: &Scene, mip: &MediumMip, walks: &Walks, s: &VplSettings, progress: &dyn Progress) -> Result<Gathered> {
    let plan = GatherPlan::new(scene, mip, walks, s)?;
    let [nx, ny, nz] = plan.grid.dims;
    let planes: Vec<Plane> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let n = (nx * ny) as usize;
            let mut plane = Plane { j: vec![Vec3::ZERO; n], iso: vec![Vec3::ZERO; n], density: vec![0.0; n], stats: GatherStats::default() };
            let mut scratch = plan.scratch();
            'rows: for jj in 0..ny {
                for i in 0..nx {
                    // Per cell: a cell connects to thousands of VPLs (a row took 300 ms).
                    if progress.cancelled() {
                        break 'rows;
                    }
                    let idx = (i + nx * jj) as usize;
                    let (rho, point) = plan.point(i, jj, k);
                    plane.density[idx] = rho;
                    let Some(p) = point else { continue };
                    let (sum, lost, iso) = plan.connect_point(&p, &mut scratch, &mut plane.stats);
                    plane.j[idx] = plan.finish(&p, sum, lost, &mut plane.stats);
                    plane.iso[idx] = plan.reweight(iso);
                }
            }
            plane
        })
        .collect();
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    let mut j = plan.grid;
    let mut density = Vec::with_capacity(j.len());
    let mut stats = GatherStats::default();
    let mut iso = Vec::with_capacity(j.len());
    for (k, plane) in planes.into_iter().enumerate() {
        let base = k * (nx * ny) as usize;
        j.data[base..base + plane.j.len()].copy_from_slice(&plane.j);
        iso.extend(plane.iso);
        density.extend(plane.density);
        stats.add(&plane.stats);
    }
    Ok(Gathered { merged: Merged { j, density }, stats, iso })
}

/// The kernel of `near_field` at a point of density `rho`, near-field radius `r`, and the ball
/// radius (at most `mean_free_paths` there: `ball_radius`) that the ball kernel takes and the
/// clamp's loss is measured against. `cone`: the ball kernel's phase-smoothing radius (0:
/// none), at most its radius. One choice for the gather and the near refinement (refine.rs).
pub fn kernel_for(near_field: NearField, medium: &Medium, rho: f32, r: f32, mean_free_paths: f32, cone: f32) -> (Kernel, f32) {
    let ball = ball_radius(medium, rho, r, mean_free_paths);
    let kernel = match near_field {
        NearField::Hat => hat(medium, rho, r),
        // (`auto` is resolved before the solve, mod.rs; as `ball` should it get here.)
        NearField::Ball | NearField::Auto => Kernel::Ball { radius: ball, cone: ball.min(cone) },
        NearField::Clamp | NearField::Compensate => Kernel::Clamp(r),
    };
    (kernel, ball)
}

/// `near_field: hat`'s kernel at a point of density `rho`, of radius `r`. Beyond the ball the
/// phases are smoothed over the ball's cone (`cone_mean_cosine` with the whole radius): the
/// VPL stands for light spread over the ball, as inside it. Measured on the dense cloud (8
/// seeds, 32768 walks, the defaults' grids): smoothing over a quarter cell as `ball` does
/// (`phase_cone`) x0.973 +- 0.014, over the whole ball x0.998 +- 0.010.
pub fn hat(medium: &Medium, rho: f32, r: f32) -> Kernel {
    Kernel::Hat { radius: r, cone: r, inside: hat_inside(medium.sigma_t(rho), r) }
}

/// The scattering-weighted mean optical radius of the near field: the sum over the voxels of
/// rho sigma_t(rho) r / the sum of rho (rho the density, sigma_t its largest channel), i.e. how
/// many mean free paths a ball of radius r spans where the medium's light typically scatters
/// (scattering, for a given light, goes with the density).
/// `near_field: auto` takes the hat where it exceeds `HAT_ABOVE` (mod.rs).
pub fn scattering_optical_radius(medium: &Medium, r: f32) -> f32 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    let mut add = |v: f32, n: f64| {
        if v > 0.0 {
            num += n * v as f64 * (medium.sigma_t(v).max_element() * r) as f64;
            den += n * v as f64;
        }
    };
    medium.grid.for_each_brick(|_, brick| match brick {
        crate::medium::grid::BrickRef::Dense(values) => values.iter().for_each(|&v| add(v, 1.0)),
        crate::medium::grid::BrickRef::Constant(v) => add(v, crate::medium::grid::BRICK_VOXELS as f64),
    });
    if den > 0.0 { (num / den) as f32 } else { 0.0 }
}

/// `near_field: auto`'s measure of a medium: `scattering_optical_radius` of the ball with the
/// volume of a cell of the medium's `AUTO_CELLS`-cell grid, i.e. how many mean free paths a
/// 16th of the medium's extent spans where its light scatters (the dense cloud fixture 2.0,
/// the plume 0.42: how many times light scatters before it leaves, which is what makes the
/// ball kernel heavy-tailed and the hat's density estimate sound).
pub fn optical_size(medium: &Medium) -> Result<f32> {
    let grid = ScatteringGrid::over_medium(medium, AUTO_CELLS)?;
    Ok(scattering_optical_radius(medium, near_field_radius(&grid.index_to_world)))
}

/// Cells of `optical_size`'s grid (the default gather's).
pub const AUTO_CELLS: u32 = 16;

/// `near_field: auto` takes the hat where `optical_size` is above this, the ball below.
/// Measured: see `NearField::Auto`.
pub const HAT_ABOVE: f32 = 0.9;

/// Radius of the ball kernel at a point of density `rho`: `r`, at most `mean_free_paths` mean
/// free paths there (0: no such limit; see the setting).
pub fn ball_radius(medium: &Medium, rho: f32, r: f32, mean_free_paths: f32) -> f32 {
    let sigma_t = medium.sigma_t(rho.max(0.0)).max_element();
    if mean_free_paths > 0.0 && sigma_t > 0.0 { r.min(mean_free_paths / sigma_t) } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::NoProgress;

    /// Exploration (not in CI): each far cluster's light against its own VPLs', summed over
    /// the gather points, per tree level, on a fixture (VPL_CLUSTER_CASE, default cube_g07;
    /// 4096 walks, the defaults): how far the cluster model is off (far_field.rs
    /// `MAX_CLUSTER_LEVEL`).
    #[test]
    #[ignore]
    fn vpl_explore_clusters_against_their_vpls() {
        let sc = crate::solvers::testing::fixture_scene(&std::env::var("VPL_CLUSTER_CASE").unwrap_or("cube_g07".into()));
        let s = VplSettings { walks: 4096, cluster_distance: 2.0, ..Default::default() };
        let mip = MediumMip::new(&sc.medium, 0.5);
        let w = super::super::walks::trace(&sc, &s, u32::MAX, &NoProgress).unwrap();
        let plan = GatherPlan::new(&sc, &mip, &w, &s).unwrap();
        let tree = &plan.far[0];
        let mut map = DepthMap::new(plan.map_resolution);
        let mut stack = Vec::new();
        // Per level: the VPLs' light, the clusters'.
        let mut sums = [[0f64; 2]; 16];
        let [nx, ny, nz] = plan.grid.dims;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let (_, Some(p)) = plan.point(i, j, k) else { continue };
                    map.build(plan.march(), p.position, plan.step, MAX_STEPS);
                    let depth = mapped_depth(plan.march(), &map, plan.map_exact, plan.step);
                    tree.visit_nodes(p.position, &mut stack, |_| {}, |c, l, cell| {
                        let mut stats = GatherStats::default();
                        let (cluster, _) = connect_clusters(plan.medium, std::slice::from_ref(c), p.position, p.view, p.kernel, &mut stats, &depth);
                        let (vpls, _, _) = connect_with(plan.medium, &tree.members(l, cell), p.position, p.view, p.kernel, p.ball, &mut stats, &depth);
                        sums[l as usize][0] += vpls.element_sum() as f64;
                        sums[l as usize][1] += cluster.element_sum() as f64;
                    });
                }
            }
        }
        for (l, [vpls, cluster]) in sums.iter().enumerate().filter(|(_, s)| s[0] > 0.0) {
            eprintln!("level {l}: the VPLs' light {vpls:.4e}, the clusters' x{:.4}", cluster / vpls);
        }
    }
}
