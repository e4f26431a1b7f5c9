//! Importance propagation (paper 01, Sec. 5.2): how much light arriving from each direction
//! of the sky reaches the camera after scattering in the medium, as a coarse lat-long map
//! that weights the choice of the dome's ordinates (translate/dome.rs). The map's type and its
//! normalisation live there; its computation is here because it runs pop's own propagation.
//!
//! By the duality of transport, importance emitted by the camera propagates like light. Steps:
//! 1. A propagation grid (`GRID_RESOLUTION` cells) aligned with the direction from the camera
//!    to the medium's centre; importance of unit fluence enters it from the camera's side;
//!    the transmittance sweep and Eq. 1-6 propagate it (init.rs, propagate.rs).
//! 2. What a distant light from sky direction w needs is the importance scattered *towards*
//!    w at each point: exactly what the accumulation of Eq. 7-8 computes with mu = d . w
//!    (accumulate.rs; it includes single scattering of the unscattered importance). J depends
//!    on w only through mu (HG lobes are symmetric about d), so it is accumulated for a few
//!    mu nodes (`MU_NODES`, denser near 1 where forward scattering is sharp) and interpolated.
//! 3. The map: I(w) = sum over cells of sigma_s T_w(x) J(x, d . w) h^3, with T_w the
//!    transmittance of light from w to the cell (a transmittance sweep along -w on a coarse
//!    grid, `SWEEP_RESOLUTION`): the paper's "ray-marching this grid". 32 x 16 texels.
//!
//! Departures: the paper's grid is perspective-warped into the camera frustum; here it is a
//! parallel grid along the central view direction (the camera as a distant importance
//! source), which is close when the medium subtends a small angle, as it does in a preview,
//! and needs nothing beyond the existing rectilinear grids. The importance propagation stops
//! after `MAX_ITERATIONS` or a residual of 1% (only the map's shape matters, and it is smooth).

use glam::Vec3;
use rayon::prelude::*;

use super::init;
use super::light_grid::LightGrid;
use crate::stages::mip::MediumMip;
use super::propagate::Propagation;
use super::accumulate;
use crate::error::Result;
use crate::medium::Medium;
use crate::scene::{Camera, LatLongMap};
use crate::stages::{CancelOnly, Progress};
use crate::translate::dome::DirectionalMap;

/// The paper's resolutions (Sec. 5.2: 16^3 and 32 x 16).
pub const GRID_RESOLUTION: u32 = 16;
pub const MAP_WIDTH: usize = 32;
pub const MAP_HEIGHT: usize = 16;
const SWEEP_RESOLUTION: u32 = 8;
const MAX_ITERATIONS: u32 = 64;
const MU_NODES: [f32; 6] = [-1.0, -0.3, 0.3, 0.7, 0.9, 1.0];

/// The directional importance map of the medium seen from `camera`, normalised to mean 1
/// over the sphere. `diffusion_correction` as in `PopSettings`. Reads `progress`'s cancel flag
/// in its propagations and per texel (`Error::Cancelled`); reports no progress of its own.
pub fn directional_importance(medium: &Medium, mip: &MediumMip, camera: &Camera, diffusion_correction: bool, progress: &dyn Progress) -> Result<DirectionalMap> {
    let (lo, hi) = medium.world_bounds();
    let view = (0.5 * (lo + hi) - camera.position).normalize_or(Vec3::Y);
    let grid = LightGrid::new(medium, mip, view, GRID_RESOLUTION)?;
    let initial = init::sweep(&grid, Vec3::ONE);
    let g = medium.g;
    // Step 2: J(x, mu) at the nodes.
    let per_node: Vec<Vec<Vec3>> = MU_NODES
        .par_iter()
        .map(|&m| {
            let mu = vec![m; grid.len()];
            let mut j = vec![Vec3::ZERO; grid.len()];
            accumulate::add_direct(&initial.direct, &mu, 1.0, g, &mut j);
            let prop = Propagation { grid: &grid, g, mu: &mu, diffusion_correction, max_iterations: MAX_ITERATIONS, residual_threshold: 1e-2 };
            prop.run(&initial, g, &mut j, &CancelOnly(progress))?;
            Ok(j)
        })
        .collect::<Result<_>>()?;
    // Step 3: per texel, light from that direction through the medium times the importance
    // scattered towards it.
    let texels: Vec<f32> = (0..MAP_WIDTH * MAP_HEIGHT)
        .into_par_iter()
        .map(|t| {
            if progress.cancelled() {
                return 0.0;
            }
            let (x, r) = (t % MAP_WIDTH, t / MAP_WIDTH);
            let w = LatLongMap::uv_to_direction([(x as f32 + 0.5) / MAP_WIDTH as f32, 1.0 - (r as f32 + 0.5) / MAP_HEIGHT as f32]);
            let mu = view.dot(w);
            let node = MU_NODES.iter().rposition(|&m| m <= mu).unwrap_or(0).min(MU_NODES.len() - 2);
            let f = ((mu - MU_NODES[node]) / (MU_NODES[node + 1] - MU_NODES[node])).clamp(0.0, 1.0);
            let Ok(lg) = LightGrid::new(medium, mip, -w, SWEEP_RESOLUTION) else { return 0.0 };
            let sweep = init::sweep(&lg, Vec3::ONE);
            let mut sum = 0.0f64;
            for k in 0..lg.dims.z {
                for j in 0..lg.dims.y {
                    for i in 0..lg.dims.x {
                        let c = lg.index(i, j, k);
                        let ss = lg.sigma_s[c].x + lg.sigma_s[c].y + lg.sigma_s[c].z;
                        if ss <= 0.0 {
                            continue;
                        }
                        let p = lg.position(i, j, k);
                        let jv = grid.sample(&per_node[node], p) * (1.0 - f) + grid.sample(&per_node[node + 1], p) * f;
                        // Channel means: one importance for all channels.
                        let t = (sweep.direct[c].x + sweep.direct[c].y + sweep.direct[c].z) / 3.0;
                        sum += (ss / 3.0 * t * (jv.x + jv.y + jv.z) / 3.0) as f64;
                    }
                }
            }
            (sum * (lg.h as f64).powi(3)) as f32
        })
        .collect();
    if progress.cancelled() {
        return Err(crate::error::Error::Cancelled);
    }
    // Normalise to mean 1 per solid angle.
    Ok(DirectionalMap::from_texels(MAP_WIDTH, MAP_HEIGHT, &texels))
}
