//! The visibility network (Sec. 3.1): for each direction, the particles binned into an M x M
//! orthographic window over the bounding sphere and sorted by depth along the direction, so
//! that each particle's upstream neighbour is the one before it in its pixel's list (what the
//! paper's depth peeling finds). Each pair's opacity is 1 - exp(-tau) with tau ray-marched
//! (settings `opacity`: by default the difference of the two particles' optical depths to the
//! boundary, else along the segment between them; the paper's tau x distance assumes a
//! homogeneous gap).

use glam::Vec3;
use rayon::prelude::*;

use super::particles::Particles;
use super::settings::Opacity;
use crate::medium::{optical_depth, Medium};
use crate::sampling::orthonormal_basis;
use crate::stages::Progress;

/// No upstream particle: the column starts at the medium's boundary.
pub const NONE: u32 = u32::MAX;

/// Most ray-march steps to the medium's boundary, and along a gap between two particles
/// (`Opacity::Segment`). A GPU backend marches with the same steps.
pub const BOUNDARY_STEPS: u32 = 512;
pub const SEGMENT_STEPS: u32 = 256;

/// The shortest ray-march step: half the smallest voxel side.
pub fn march_step(medium: &Medium) -> f32 {
    medium.voxel_size_world().min_element() * 0.5
}

/// The sort key of particle `index` at `x` for direction `w` (basis `u`, `v`) in an `m` x `m`
/// window over the sphere (`centre`, `radius`): its pixel (u fastest), its depth x . w as a
/// u32 that orders like `f32::total_cmp`, and its index. Lists are these keys in ascending
/// order (ties in pixel and depth broken by index, so the order is deterministic).
pub fn sort_key(x: Vec3, index: u32, (u, v, w): (Vec3, Vec3, Vec3), centre: Vec3, radius: f32, m: u32) -> (u64, u32, u32) {
    let r = x - centre;
    (window_cell(r.dot(u), radius, m) + m as u64 * window_cell(r.dot(v), radius, m), total_order_bits(x.dot(w)), index)
}

/// The window column of coordinate `a` (from the sphere's centre, along u or v) in an `m`-wide
/// window over the sphere of `radius`: floor, clamped to the window.
pub fn window_cell(a: f32, radius: f32, m: u32) -> u64 {
    (((a + radius) / (2.0 * radius) * m as f32).floor() as i64).clamp(0, m as i64 - 1) as u64
}

/// f32 bits as a u32 whose unsigned order is `f32::total_cmp`'s.
pub fn total_order_bits(a: f32) -> u32 {
    let b = a.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// One direction's lists.
pub struct DirectionLinks {
    /// Particles by pixel, then by depth along the direction (upstream first): a sweep in this
    /// order meets every particle after its upstream neighbour.
    pub order: Vec<u32>,
    /// Per particle: its upstream neighbour, or `NONE`.
    pub up: Vec<u32>,
    /// Per particle: the opacity of the gap from its upstream neighbour (RGB); without one, of
    /// the gap from the medium's boundary.
    pub alpha: Vec<Vec3>,
}

/// The window side M: the paper's bound M^2 <= D (R tau)^2 / pi, which keeps a neighbour's
/// solid angle (the pixel's area at the mean free path) above one direction's 4 pi / D,
/// clamped to [2, sqrt(N)] so that a pixel holds particles at all.
pub fn window_side(requested: u32, directions: u32, radius: f32, mean_sigma_t: f32, particles: usize) -> u32 {
    if requested > 0 {
        return requested;
    }
    let rt = radius * mean_sigma_t;
    let m = (directions as f32 * rt * rt / std::f32::consts::PI).sqrt().floor() as u32;
    m.clamp(2, ((particles as f32).sqrt() as u32).max(2))
}

/// The links of every direction in `dirs` (directions light travels); `None` once the host
/// cancels (a direction is a few ms, the whole build seconds at 8192 x 1024).
#[allow(clippy::too_many_arguments)]
pub fn build(medium: &Medium, p: &Particles, dirs: &[Vec3], centre: Vec3, radius: f32, m: u32, opacity: Opacity, progress: &dyn Progress) -> Option<Vec<DirectionLinks>> {
    let step = march_step(medium);
    dirs.par_iter()
        .map(|&w| {
            if progress.cancelled() {
                return None;
            }
            let (u, v) = orthonormal_basis(w);
            let mut keyed: Vec<(u64, u32, u32)> = p.position.iter().enumerate().map(|(i, &x)| sort_key(x, i as u32, (u, v, w), centre, radius, m)).collect();
            // Keys are unique (the index): any sort gives the same order.
            keyed.sort_unstable();
            let n = p.len();
            let mut up = vec![NONE; n];
            let mut alpha = vec![Vec3::ZERO; n];
            let boundary = |x: Vec3| optical_depth(medium, x, -w, f32::INFINITY, step, BOUNDARY_STEPS);
            let mut to_boundary = vec![Vec3::ZERO; n];
            if opacity == Opacity::Boundary {
                for (i, t) in to_boundary.iter_mut().enumerate() {
                    *t = boundary(p.position[i]);
                }
            }
            for (k, key) in keyed.iter().enumerate() {
                let b = key.2 as usize;
                let x = p.position[b];
                let tau = match k.checked_sub(1).map(|k| keyed[k]).filter(|prev| prev.0 == key.0) {
                    Some(prev) => {
                        let a = prev.2 as usize;
                        up[b] = a as u32;
                        match opacity {
                            // Clipped at 0 where the neighbour's ray is the denser one.
                            Opacity::Boundary => (to_boundary[b] - to_boundary[a]).max(Vec3::ZERO),
                            // Light crosses the gap's depth along w, not the slanted segment
                            // between the two (laterally up to a pixel apart): the segment's
                            // optical depth per metre times the depth gap. The slanted length
                            // overcounts extinction and scattering alike (measured: white
                            // furnace box 1.18 with the full segment, 1.06 so).
                            Opacity::Segment => {
                                let gap = x - p.position[a];
                                let len = gap.length();
                                if len > 0.0 {
                                    optical_depth(medium, p.position[a], gap / len, len, step, SEGMENT_STEPS) * (gap.dot(w).max(0.0) / len)
                                } else {
                                    Vec3::ZERO
                                }
                            }
                        }
                    }
                    // The column's first particle: the gap from the medium's boundary.
                    None if opacity == Opacity::Boundary => to_boundary[b],
                    None => boundary(x),
                };
                alpha[b] = Vec3::ONE - (-tau).exp();
            }
            // Each pixel's list is contiguous and upstream first, which is all a sweep needs.
            let order = keyed.iter().map(|k| k.2).collect();
            Some(DirectionLinks { order, up, alpha })
        })
        .collect()
}
