//! Node values for a product grid S = sigma_s J that a renderer will interpolate trilinearly.
//!
//! Why: a host renders S as volume emission, looking it up trilinearly between grid points,
//! and so does our compositor. When the grid is the medium's own voxel lattice the density is
//! trilinear on it too, and S's true integral over a cell is that of the product of two
//! interpolants, not the interpolant of the products at the nodes: per lattice edge the two
//! differ by (d_b - d_a)(K_b - K_a) / 6, and wherever J falls as the density rises (a lit
//! surface, a dense wisp in a light's shadow) the node products lose it. These edge terms are
//! moved into the node values, so that the sum of the nodes, which is the interpolant's
//! integral, matches the product's for J linear over each cell:
//!
//!   S_i = d_i K_i - 1/12 sum over the six neighbours n of w_n (d_n - d_i)(K_n - K_i)
//!
//! with d the density at the nodes and K = albedo density_scale J (so d K = sigma_s J), and
//! each edge's term shared by its two nodes (w = 1) unless one of them is empty: then the
//! other takes it whole (w = 2), and an empty node's S stays zero (no emission where the
//! host's density is zero at the node). No solver knows J at an empty node, so there K is
//! extrapolated through the node from the opposite one as a transmittance (`through`).
//! Not moved: J's own curvature over a cell (the trapezoid rule's h^2 J'' / 12): its discrete
//! Laplacian sharpens the Monte Carlo solvers' noise. On a grid coarser than the lattice the
//! density at the nodes is a point sample of a finer field and the terms do not hold, and
//! nothing is changed. The measurements behind these choices: docs/architecture.md.

use glam::{Affine3A, Vec3};
use rayon::prelude::*;

use crate::medium::Medium;
use crate::stages::ScatteringGrid;

/// Whether the grid's points are the medium's voxel centres, or the points of that lattice
/// refined n times (spacing 1 / n voxel along the same axes, offset a multiple of it): what
/// `ScatteringGrid::over_medium` gives when the medium has no more voxels than the grid's
/// largest side allows. On either the medium's trilinear density is trilinear between the
/// grid's points, which the module's terms assume.
pub fn on_voxel_lattice(medium: &Medium, grid_index_to_world: &Affine3A) -> bool {
    let m = medium.world_to_index * *grid_index_to_world;
    let n = (1.0 / m.matrix3.x_axis.x).round().max(1.0);
    let unit = (glam::Mat3::from(m.matrix3) * n - glam::Mat3::IDENTITY).to_cols_array().iter().all(|e| e.abs() < 1e-4 * n);
    let t = Vec3::from(m.translation) * n;
    unit && (t - t.round()).abs().max_element() < 1e-3 * n
}

/// S's node values for trilinear rendering (the module's formula), in place, where `grid` is on
/// the medium's voxel lattice; any other grid is left as it is. Every solver calls it once on
/// the S it returns, single and multiple scattering together (in a white furnace, where their
/// sum is uniform, it changes nothing, which the single part alone would not be); and the
/// compositor calls it on its single-scattering AOV. Memory: three planes of the grid at a
/// time, not a second grid (S of a large medium takes what memory the solve could have).
pub fn finish(medium: &Medium, grid: &mut ScatteringGrid) {
    if !on_voxel_lattice(medium, &grid.index_to_world) {
        return;
    }
    let [nx, ny, _] = grid.dims.map(|d| d as usize);
    let frame = grid.index_to_world;
    let plane = |z: usize| -> Vec<f32> {
        (0..nx * ny).into_par_iter().map(|i| medium.density_world(frame.transform_point3(Vec3::new((i % nx) as f32, (i / nx) as f32, z as f32)))).collect()
    };
    product_nodes(grid.dims, plane, &mut grid.data);
}

/// `finish` on a grid that is handed on.
pub fn finished(medium: &Medium, mut grid: ScatteringGrid) -> ScatteringGrid {
    finish(medium, &mut grid);
    grid
}

/// Planes z - 1, z, z + 1 of the node densities and of the plain products s (empty slices past
/// the grid's ends).
struct Planes<'a> {
    d: [&'a [f32]; 3],
    s: [&'a [Vec3]; 3],
    nx: usize,
    ny: usize,
}

impl Planes<'_> {
    /// (density, s) of node (x, y) of plane `p` (0, 1, 2 for z - 1, z, z + 1) offset by (dx, dy),
    /// None past the grid.
    #[inline]
    fn at(&self, p: usize, x: usize, y: usize, dx: isize, dy: isize) -> Option<(f32, Vec3)> {
        let (x, y) = (x.checked_add_signed(dx)?, y.checked_add_signed(dy)?);
        if x >= self.nx || y >= self.ny || self.d[p].is_empty() {
            return None;
        }
        let i = x + self.nx * y;
        Some((self.d[p][i], self.s[p][i]))
    }
}

/// The module's node values, in place over `s` (the plain products sigma_s J on a grid of
/// `dims`), with `density_plane(z)` the node densities of plane z. K = s / d where there is
/// density; at an empty neighbour, whose J no solver knows, K is extrapolated through the node
/// from the one opposite (`through`; K_i where that one is empty too or past the grid). Empty
/// nodes keep their s. Clamped at zero: S is emission (reached only where the curvature term
/// outweighs a faint node).
pub fn product_nodes(dims: [u32; 3], density_plane: impl Fn(usize) -> Vec<f32>, s: &mut [Vec3]) {
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let len = nx * ny;
    let (mut d_prev, mut d_cur) = (Vec::new(), density_plane(0));
    let mut s_prev: Vec<Vec3> = Vec::new();
    for z in 0..nz {
        let d_next = if z + 1 < nz { density_plane(z + 1) } else { Vec::new() };
        let s_cur = s[z * len..(z + 1) * len].to_vec();
        let (done, rest) = s.split_at_mut((z + 1) * len);
        let planes = Planes { d: [&d_prev, &d_cur, &d_next], s: [&s_prev, &s_cur, &rest[..d_next.len()]], nx, ny };
        done[z * len..].par_iter_mut().enumerate().for_each(|(i, out)| *out = node(&planes, i % nx, i / nx));
        (d_prev, d_cur, s_prev) = (d_cur, d_next, s_cur);
    }
}

/// One node's value (x, y) of the middle plane.
#[inline]
fn node(planes: &Planes, x: usize, y: usize) -> Vec3 {
    let (d, s) = planes.at(1, x, y, 0, 0).expect("the node itself");
    if d <= 0.0 {
        return s;
    }
    let k = s / d;
    let k_of = |n: Option<(f32, Vec3)>| n.filter(|n| n.0 > 0.0).map(|n| (n.0, n.1 / n.0));
    let mut correction = Vec3::ZERO;
    // The two neighbours along each axis: (plane, dx, dy) on either side.
    for [(pa, xa, ya), (pb, xb, yb)] in [[(1, 1, 0), (1, -1, 0)], [(1, 0, 1), (1, 0, -1)], [(2, 0, 0), (0, 0, 0)]] {
        let (a, b) = (planes.at(pa, x, y, xa, ya), planes.at(pb, x, y, xb, yb));
        let (ka, kb) = (k_of(a), k_of(b));
        // K beyond the node on one side: its own where it has density, else through the node
        // from the other side (or the node's own: no term).
        let beyond = |near: Option<(f32, Vec3)>, far: Option<(f32, Vec3)>| near.map_or_else(|| far.map_or(k, |(df, kf)| through(d, k, df, kf)), |n| n.1);
        let (ka, kb) = (beyond(ka, kb), beyond(kb, ka));
        for (n, kn) in [(a, ka), (b, kb)] {
            let Some((dn, _)) = n else { continue };
            // An edge to an empty node is all this node's: the empty one emits nothing.
            let share = if dn > 0.0 { 1.0 } else { 2.0 };
            correction += share * (dn - d) * (kn - k);
        }
    }
    (d * k - correction / 12.0).max(Vec3::ZERO)
}

/// K one node beyond a node (density `d`, K `k`) towards an empty node, opposite a node (`d_opp`,
/// `k_opp`): J across a lit surface changes as the transmittance, so the step's ratio is the
/// opposite step's, raised to the ratio of their optical depths (the mean densities of the two
/// edges: the ramp to the empty node has half the node's): K (K / K_opp)^(d / (d + d_opp)),
/// the ratio at most `MAX_STEP` per channel (a faint opposite node).
#[inline]
fn through(d: f32, k: Vec3, d_opp: f32, k_opp: Vec3) -> Vec3 {
    let ratio = Vec3::select(k_opp.cmpgt(Vec3::ZERO), k / k_opp, Vec3::splat(MAX_STEP)).min(Vec3::splat(MAX_STEP));
    let e = d / (d + d_opp);
    k * Vec3::new(ratio.x.powf(e), ratio.y.powf(e), ratio.z.powf(e))
}

/// The largest step `through` extrapolates, K_out / K_i: about e^1.4, a node of optical depth 1.4.
const MAX_STEP: f32 = 4.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// 1D along x (dims n x 1 x 1): light entering from the left through a density that ramps
    /// up from empty nodes, thins out and thickens again, K = e^-tau with tau 0.6 times the
    /// integral of the interpolated density (up to 1.2 a node: a steep, lit surface). The true
    /// integral of the interpolated density times K (fine quadrature) against the node sums:
    /// the plain products are 4.7% low, these nodes 1.8% high (J's own curvature, not moved:
    /// module doc); bound: half the plain error. And the empty nodes stay at zero.
    #[test]
    fn a_lit_surface_integrates_closer() {
        let n = 12usize;
        let d: Vec<f32> = (0..n).map(|i| if i < 2 || i >= n - 2 { 0.0 } else { 1.0 + (0.9 * i as f32).sin() }).collect();
        let interp = |x: f64| {
            let a = (x as usize).min(n - 2);
            let t = x - a as f64;
            (1.0 - t) * d[a] as f64 + t * d[a + 1] as f64
        };
        let steps = 2000;
        let h = 1.0 / steps as f64;
        let (mut tau, mut exact) = (0.0f64, 0.0f64);
        let mut k = vec![Vec3::ONE; n];
        for a in 0..n - 1 {
            for q in 0..steps {
                let dens = interp(a as f64 + (q as f64 + 0.5) * h);
                exact += dens * (-0.6 * (tau + 0.5 * dens * h)).exp() * h;
                tau += dens * h;
            }
            k[a + 1] = Vec3::splat((-0.6 * tau).exp() as f32);
        }
        let mut s: Vec<Vec3> = k.iter().zip(&d).map(|(k, &d)| *k * d).collect();
        let plain: f64 = s.iter().map(|v| v.x as f64).sum();
        product_nodes([n as u32, 1, 1], |_| d.clone(), &mut s);
        let ours: f64 = s.iter().map(|v| v.x as f64).sum();
        let (e_plain, e_ours) = ((plain - exact).abs() / exact, (ours - exact).abs() / exact);
        eprintln!("exact {exact:.5}, plain {plain:.5} ({e_plain:.4}), ours {ours:.5} ({e_ours:.4})");
        assert!(e_plain > 0.02, "the case should need the correction: {e_plain}");
        assert!(e_ours < 0.5 * e_plain, "ours {e_ours} against plain {e_plain}");
        assert!(s.iter().zip(&d).all(|(v, &d)| d > 0.0 || *v == Vec3::ZERO), "an empty node emits: {s:?}");
    }

    /// A uniform K over uniform density is left as it is, and an empty grid stays empty.
    #[test]
    fn uniform_and_empty_fields_are_unchanged() {
        let dims = [4, 4, 4];
        let d = vec![2.0f32; 64];
        let k = vec![Vec3::new(1.0, 2.0, 3.0); 64];
        let mut s: Vec<Vec3> = k.iter().map(|k| *k * 2.0).collect();
        product_nodes(dims, |_| d[..16].to_vec(), &mut s);
        assert!(s.iter().all(|v| (*v - Vec3::new(2.0, 4.0, 6.0)).abs().max_element() < 1e-6));
        let mut empty = vec![Vec3::ZERO; 64];
        product_nodes(dims, |_| vec![0.0; 16], &mut empty);
        assert!(empty.iter().all(|v| *v == Vec3::ZERO));
    }
}
