//! Random walks from the lights (paper 03 Sec. 4.1): rays from the shared light sampling
//! (translate::LightSampler, every light type), spectral free-flight tracking through the
//! heterogeneous medium (medium::Tracking), HG scattering, albedo weights and Russian roulette.
//! Each real collision leaves an anisotropic VPL: the power scattered there (the walk's
//! throughput times the albedo), the direction the light arrived along (its HG lobe is turned
//! to it) and the position. The first VPL is the walk's first collision in the medium: the
//! light that reaches a point straight from a light source is single scattering, which the
//! solver takes exactly from the compositor's grid, so it is never counted twice.

use glam::Vec3;
use rayon::prelude::*;

use super::settings::VplSettings;
use crate::medium::{FreeFlight, MajorantGrid, Tracking};
use crate::phase::HenyeyGreenstein;
use crate::rng::Rng;
use crate::error::Result;
use crate::scene::Scene;
use crate::stages::Progress;
use crate::translate::LightSampler;

/// One virtual point light.
#[derive(Clone, Copy, Debug)]
pub struct Vpl {
    pub position: Vec3,
    /// Propagation direction of the light arriving at the VPL (unit).
    pub incident: Vec3,
    /// Power it scatters (W, RGB), already divided by the number of walks.
    pub power: Vec3,
}

/// The VPLs of all walks, grouped by walk: walk w's are `vpls[offsets[w]..offsets[w + 1]]`.
pub struct Walks {
    pub vpls: Vec<Vpl>,
    pub offsets: Vec<usize>,
    /// Walks cut at `max_vertices` (a bias: counted so that it is seen).
    pub cut: u32,
}

impl Walks {
    pub fn count(&self) -> usize {
        self.offsets.len() - 1
    }
    pub fn of_walk(&self, w: usize) -> &[Vpl] {
        &self.vpls[self.offsets[w]..self.offsets[w + 1]]
    }
    /// Total power the VPLs scatter (W, RGB).
    pub fn total_power(&self) -> Vec3 {
        self.vpls.iter().map(|v| v.power).sum()
    }
}

/// `max_orders`: keep only the first this many VPLs of each walk and stop it there (tests: 1
/// gives double scattering alone); u32::MAX for full transport.
/// Once `progress` is cancelled the remaining walks are skipped (each walk is microseconds):
/// the result is then `Error::Cancelled`.
pub fn trace(scene: &Scene, settings: &VplSettings, max_orders: u32, progress: &dyn Progress) -> Result<Walks> {
    let medium = &scene.medium;
    let sampler = LightSampler::new(scene);
    let majorant = MajorantGrid::new(medium, 32);
    let tracking = Tracking::new(medium, &majorant);
    let phase = HenyeyGreenstein::new(medium.g);
    let n = settings.walks;
    // One (list, cut) entry per walk before they are packed; the VPLs themselves are not
    // known in advance (a few per walk in the media this is meant for).
    crate::budget::check_elements::<(Vec<Vpl>, bool)>("vpl walk lists (solver.walks)", n as u64)?;
    let per_walk: Vec<(Vec<Vpl>, bool)> = (0..n)
        .into_par_iter()
        .map(|w| {
            // None ends the collection (`while_some`): visiting millions of skipped walks
            // would itself take most of a second.
            if progress.cancelled() {
                return None;
            }
            let mut out = Vec::new();
            let mut rng = Rng::new(settings.seed, w as u64);
            let Some(ray) = sampler.sample_rng(&mut rng) else { return Some((out, false)) };
            let (mut x, mut d) = (ray.origin, ray.direction);
            let start = ray.power / n as f32;
            let mut beta = start;
            let limit = settings.max_vertices.min(max_orders);
            loop {
                if out.len() as u32 >= limit {
                    return Some((out, limit == settings.max_vertices && max_orders == u32::MAX));
                }
                match tracking.sample_free_flight(x, d, f32::INFINITY, beta, &mut rng) {
                    FreeFlight::Escaped { .. } => return Some((out, false)),
                    FreeFlight::Scattered { t, weight } => {
                        x += d * t;
                        beta = weight * medium.albedo;
                        if beta.max_element() <= 0.0 {
                            return Some((out, false));
                        }
                        out.push(Vpl { position: x, incident: d, power: beta });
                        if out.len() as u32 >= settings.rr_depth {
                            // Survival in proportion to the throughput left (at most 1).
                            let p = (beta.max_element() / start.max_element().max(1e-30)).min(1.0);
                            if rng.f32() >= p {
                                return Some((out, false));
                            }
                            beta /= p;
                        }
                        d = phase.sample(d, rng.pair());
                    }
                }
            }
        })
        .while_some()
        .collect();
    if progress.cancelled() {
        // Millions of small lists take a third of a second of CPU to free at 16M walks: they
        // are freed on a thread of their own, so that a cancelled solve returns at once.
        // Without a thread to be had, the closure and the lists in it are dropped here.
        let _ = std::thread::Builder::new().name("vpl-free".into()).spawn(move || drop(per_walk));
        return Err(crate::error::Error::Cancelled);
    }
    let mut offsets = Vec::with_capacity(per_walk.len() + 1);
    offsets.push(0);
    let mut vpls = Vec::new();
    let mut cut = 0;
    for (v, c) in per_walk {
        vpls.extend(v);
        offsets.push(vpls.len());
        cut += c as u32;
    }
    Ok(Walks { vpls, offsets, cut })
}
