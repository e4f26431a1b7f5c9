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
    let majorant = MajorantGrid::new(medium, 32);
    let n = settings.walks;
    let walker = Walker {
        settings,
        max_orders,
        sampler: LightSampler::new(scene),
        tracking: Tracking::new(medium, &majorant),
        phase: HenyeyGreenstein::new(medium.g),
        medium,
        walks: n,
    };
    // Walks are traced in blocks, each packing its walks' VPLs into one list: the VPLs are
    // not known in advance (a few per walk in the media this is meant for), and millions of
    // per-walk lists took a third of a second of CPU to free after a cancel at 16M walks.
    crate::budget::check_elements::<usize>("vpl walk offsets (solver.walks)", n as u64 + 1)?;
    let blocks: Vec<WalkBlock> = (0..n.div_ceil(WALK_BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut block = WalkBlock::default();
            for w in b * WALK_BLOCK..((b + 1) * WALK_BLOCK).min(n) {
                // None ends the collection (`while_some`): visiting millions of skipped walks
                // would itself take most of a second.
                if progress.cancelled() {
                    return None;
                }
                block.cut += trace_walk(&walker, w, &mut block.vpls) as u32;
                block.ends.push(block.vpls.len());
            }
            Some(block)
        })
        .while_some()
        .collect();
    if progress.cancelled() {
        return Err(crate::error::Error::Cancelled);
    }
    let mut offsets = Vec::with_capacity(n as usize + 1);
    offsets.push(0);
    let mut vpls = Vec::with_capacity(blocks.iter().map(|b| b.vpls.len()).sum());
    let mut cut = 0;
    for b in blocks {
        let base = vpls.len();
        offsets.extend(b.ends.iter().map(|e| base + e));
        vpls.extend(b.vpls);
        cut += b.cut;
    }
    Ok(Walks { vpls, offsets, cut })
}

/// Walks traced together, their VPLs packed: walk i of the block ends at `vpls[..ends[i]]`.
#[derive(Default)]
struct WalkBlock {
    vpls: Vec<Vpl>,
    ends: Vec<usize>,
    cut: u32,
}

/// Walks per block: enough that a block's lists are few to free, few enough (milliseconds of
/// work) that the blocks spread over the workers.
const WALK_BLOCK: u32 = 1024;

/// What every walk of a solve shares.
struct Walker<'a> {
    settings: &'a VplSettings,
    max_orders: u32,
    sampler: LightSampler<'a>,
    tracking: Tracking<'a>,
    phase: HenyeyGreenstein,
    medium: &'a crate::medium::Medium,
    walks: u32,
}

/// Traces walk `w`, appending its VPLs to `out`; true when it was cut at `max_vertices`.
fn trace_walk(walker: &Walker, w: u32, out: &mut Vec<Vpl>) -> bool {
    let Walker { settings, max_orders, sampler, tracking, phase, medium, walks: n } = walker;
    let (max_orders, n) = (*max_orders, *n);
    let first = out.len();
    let mut rng = Rng::new(settings.seed, w as u64);
    let Some(ray) = sampler.sample_rng(&mut rng) else { return false };
    let (mut x, mut d) = (ray.origin, ray.direction);
    let start = ray.power / n as f32;
    let mut beta = start;
    let limit = settings.max_vertices.min(max_orders);
    loop {
        let made = (out.len() - first) as u32;
        if made >= limit {
            return limit == settings.max_vertices && max_orders == u32::MAX;
        }
        match tracking.sample_free_flight(x, d, f32::INFINITY, beta, &mut rng) {
            FreeFlight::Escaped { .. } => return false,
            FreeFlight::Scattered { t, weight } => {
                x += d * t;
                beta = weight * medium.albedo;
                if beta.max_element() <= 0.0 {
                    return false;
                }
                out.push(Vpl { position: x, incident: d, power: beta });
                if made + 1 >= settings.rr_depth {
                    // Survival in proportion to the throughput left (at most 1).
                    let p = (beta.max_element() / start.max_element().max(1e-30)).min(1.0);
                    if rng.f32() >= p {
                        return false;
                    }
                    beta /= p;
                }
                d = phase.sample(d, rng.pair());
            }
        }
    }
}
