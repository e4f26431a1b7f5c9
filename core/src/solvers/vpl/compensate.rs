//! Bias compensation of the clamped near field (paper 03 Sec. 4.3-4.4).
//!
//! With G clamped to 1/R^2, a point x misses, from the light scattered within R of it,
//!   M(x, o) = integral dw p(w . o) integral_0^R dt T(x, x') (1 - t^2/R^2) eps(x', w),
//! x' = x - w t, o the direction the light leaves x in, eps(x', w) the light x' scatters
//! towards x (per unit volume): sigma_s(x') [direct light scattered into w (the compositor's
//! `DirectLight`) + the VPLs' light at x' (clamped again) + M(x', w)] -- the VPLs stand for the
//! light scattered at least once, so the direct light is the compensation's first VPL.
//! (1 - t^2/R^2) = t^2 (1/t^2 - 1/R^2) is the clamped fraction of G times the volume's
//! Jacobian; it is the paper's weight max(0, (G - b)/G) restricted to t < R, where it is not
//! zero.
//!
//! Sampling, as the paper: w from the phase function at x (its factor cancels), t in [0, R]
//! from the locally homogeneous exponential p(t) = s exp(-s t) / (1 - exp(-s R)), s the
//! extinction of the density mip around x; the true transmittance T(x, x') is ray marched, so
//! the estimate stays unbiased whatever s is. Each new vertex connects to one randomly chosen
//! subset of walks (Sec. 4.4, "sub-sampling random walks"), reweighted by the number of
//! subsets. `compensation_vertices` vertices at the first level, one per vertex below it
//! (Fig. 4's middle strategy); at the last level (`compensation_depth`) the vertices take the
//! VPLs with the ball kernel of radius R instead of the clamp ("stopping the compensation
//! using the unclamped contribution", Sec. 4.4): its integral is that of 1/d^2, so nothing is
//! left out at any depth, and it stays bounded (3/R^2). The radius is R, not `near_field:
//! ball`'s quarter mean free path, which made the dense cloud heavy-tailed (docs/solvers/vpl.md).
//!
//! The estimate is made in two steps, `vertices` (every random number, the direct light) then
//! `combine` over the vertices' connections to their VPLs, which use no random number: the
//! CPU connects vertex by vertex (`estimate`), the GPU backend all vertices of all gather
//! points in one batch; both combine in the same order.
//!
//! Departure: visibility is the medium's transmittance only (no surfaces in this project), so
//! the paper's local-visibility approximation is not needed.

use glam::Vec3;
use std::sync::Arc;

use super::gather::{connect, subset_lists, GatherStats, Kernel};
use super::march::Marcher;
use super::settings::VplSettings;
use super::walks::{Vpl, Walks};
use crate::stages::single_scattering::DirectLight;
use crate::medium::{optical_depth, Medium};
use crate::phase::HenyeyGreenstein;
use crate::rng::Rng;
use crate::scene::Scene;
use crate::stages::mip::MediumMip;

/// Share of the compensation's distances drawn from the locally homogeneous exponential (the
/// rest uniform on [0, R]).
const EXPONENTIAL_SHARE: f32 = 0.75;

pub struct Compensation<'a> {
    medium: &'a Medium,
    mip: &'a MediumMip,
    /// Footprint (index units) of the mip lookups for the local extinction.
    footprint: f32,
    direct: DirectLight<'a>,
    lists: Vec<Vec<Vpl>>,
    /// Clamp radius R.
    radius: f32,
    /// Transmittance march step to the VPLs, and along the short segments x -> x'.
    step: f32,
    short_step: f32,
    phase: HenyeyGreenstein,
    vertices: u32,
    depth: u32,
    /// The connections' transmittance march (shared with the gather plan).
    march: Arc<Marcher<'a>>,
}

impl<'a> Compensation<'a> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(scene: &'a Scene, mip: &'a MediumMip, footprint: f32, walks: &Walks, s: &VplSettings, radius: f32, step: f32, march: Arc<Marcher<'a>>) -> Self {
        let medium = &scene.medium;
        let subsets = (walks.count() as u32 / s.compensation_walks.max(1)).clamp(1, walks.count().max(1) as u32);
        let short_step = 0.5 * medium.voxel_size_world().min_element();
        Compensation {
            medium,
            mip,
            footprint,
            direct: DirectLight::with_march(scene, step, s.dome_directions, radius, march.clone()),
            lists: subset_lists(walks, subsets),
            radius,
            step,
            short_step,
            phase: HenyeyGreenstein::new(medium.g),
            vertices: s.compensation_vertices,
            depth: s.compensation_depth,
            march,
        }
    }

    /// M(x, out) of the module doc, per unit sigma_s at x (new vertices around a gather point,
    /// recursively): `vertices`, each connected on the CPU, then `combine`.
    pub fn estimate(&self, x: Vec3, out: Vec3, rng: &mut Rng, stats: &mut GatherStats) -> Vec3 {
        let nodes = self.vertices(x, out, rng, stats);
        let light: Vec<Vec3> = nodes
            .iter()
            .map(|v| {
                let (kernel, ball) = self.kernel(v);
                connect(&self.march, &self.lists[v.list as usize], v.position, v.view, kernel, ball, self.step, stats).0
            })
            .collect();
        self.combine(&nodes, &light)
    }

    /// The VPL lists the vertices connect to (`Vertex::list` indexes them).
    pub fn lists(&self) -> &[Vec<Vpl>] {
        &self.lists
    }

    /// Transmittance march step of the vertices' connections.
    pub fn step(&self) -> f32 {
        self.step
    }

    /// The kernel a vertex takes the VPLs with, and the ball radius of `connect`'s report.
    pub fn kernel(&self, v: &Vertex) -> (Kernel, f32) {
        (if v.last { Kernel::Ball { radius: self.radius, cone: 0.0 } } else { Kernel::Clamp(self.radius) }, self.radius)
    }

    /// The compensation's vertices around a gather point x (light leaving it along `out`), in
    /// depth-first order, each followed by its subtree: everything of the estimate but the
    /// connections to the VPLs, which depend on no random number (so a backend may make
    /// them all at once, then `combine`).
    pub fn vertices(&self, x: Vec3, out: Vec3, rng: &mut Rng, stats: &mut GatherStats) -> Vec<Vertex> {
        let mut nodes = Vec::new();
        self.sample(x, out, 1, rng, stats, &mut nodes);
        nodes
    }

    /// Vertices at recursion `level` (1: around a gather point) appended to `nodes`.
    fn sample(&self, x: Vec3, out: Vec3, level: u32, rng: &mut Rng, stats: &mut GatherStats, nodes: &mut Vec<Vertex>) {
        let m = self.medium;
        let r = self.radius;
        let n = if level == 1 { self.vertices } else { 1 };
        let rho = self.mip.sample(m, m.world_to_index.transform_point3(x), self.footprint);
        let s = m.sigma_t(rho.max(0.0)).max_element();
        let alpha = -(-s * r).exp_m1();
        for _ in 0..n {
            stats.vertices += 1;
            // Propagation direction of the light arriving at x, density p(w . out).
            let w = self.phase.sample(out, rng.pair());
            // Defensive mixture: the exponential with probability 3/4, uniform on [0, R]
            // otherwise, so that the weight T / pdf stays below 4 R where the medium is
            // thinner than the mip's mean (the exponential alone gives exp(s R) / s there).
            let u = rng.f32();
            let t = if u < EXPONENTIAL_SHARE && s * r > 1e-4 {
                let v = u / EXPONENTIAL_SHARE;
                (-(-v * alpha).ln_1p() / s).min(r)
            } else {
                r * ((u - EXPONENTIAL_SHARE) / (1.0 - EXPONENTIAL_SHARE)).clamp(0.0, 1.0)
            };
            let exponential = if s * r > 1e-4 { s * (-s * t).exp() / alpha } else { 1.0 / r };
            let pdf = EXPONENTIAL_SHARE * exponential + (1.0 - EXPONENTIAL_SHARE) / r;
            let xp = x - w * t;
            let rho_p = m.density_world(xp);
            if rho_p <= 0.0 || pdf <= 0.0 {
                continue;
            }
            let tr = (-optical_depth(m, xp, w, t, self.short_step, 256)).exp();
            let weight = tr * ((1.0 - t * t / (r * r)).max(0.0) / pdf);
            // At x' the viewer is x: the scattered light propagates along w, so view = -w.
            let view = -w;
            let direct = self.direct.inscattered(xp, view);
            let k = (rng.f32() * self.lists.len() as f32) as usize;
            let at = nodes.len();
            let last = level >= self.depth;
            nodes.push(Vertex { position: xp, view, list: k.min(self.lists.len() - 1) as u32, last, factor: weight * m.sigma_s(rho_p), direct, subtree: 1 });
            if !last {
                self.sample(xp, w, level + 1, rng, stats, nodes);
                nodes[at].subtree = (nodes.len() - at) as u32;
            }
        }
    }

    /// The estimate from the vertices (`vertices`) and each one's connection to its VPLs
    /// (`connect`'s sum, same order).
    pub fn combine(&self, nodes: &[Vertex], light: &[Vec3]) -> Vec3 {
        self.combine_group(nodes, light, 0, nodes.len(), self.vertices)
    }

    /// The mean over `n` samples of the vertices nodes[start..end] (siblings and their subtrees).
    fn combine_group(&self, nodes: &[Vertex], light: &[Vec3], start: usize, end: usize, n: u32) -> Vec3 {
        let scale = self.lists.len() as f32;
        let mut sum = Vec3::ZERO;
        let mut i = start;
        while i < end {
            let v = &nodes[i];
            let next = i + v.subtree as usize;
            let mut eps = v.direct;
            if v.last {
                eps += light[i] * scale;
            } else {
                eps += light[i] * scale + self.combine_group(nodes, light, i + 1, next, 1);
            }
            sum += v.factor * eps;
            i = next;
        }
        sum / n.max(1) as f32
    }
}

/// One vertex of the compensation (`Compensation::vertices`).
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub position: Vec3,
    /// Direction the vertex is seen from (`connect`'s view): the light it scatters goes to
    /// its parent.
    pub view: Vec3,
    /// Its subset of walks (an index into `Compensation::lists`).
    pub list: u32,
    /// At the last recursion level: takes the VPLs with the ball kernel, has no children.
    pub last: bool,
    /// Its weight (transmittance / pdf, the clamp's share) times sigma_s there.
    pub factor: Vec3,
    /// The direct light it scatters towards its parent.
    pub direct: Vec3,
    /// Nodes in its subtree, itself included.
    pub subtree: u32,
}
