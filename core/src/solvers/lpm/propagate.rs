//! The propagate step (Sec. 4.1, Eq. 3 and 6): one face's map of rays, all of one direction,
//! marched layer by layer along the face's axis through a slab of layers. Rays of one
//! direction never share a cell within a layer, so each writes its own cell of the
//! direction's temporary buffer T without atomics (Fig. 3, right).
//!
//! Geometry: the map holds one ray per cell of a layer. From layer w - 1 to w every ray moves
//! laterally by round(a w) - round(a (w - 1)) cells along u (in {-1, 0, 1}, |a| < 1), and
//! likewise along v: the whole map shifts, so each cell of the new layer again holds exactly
//! one ray, and a ray that leaves through a side face re-enters at the opposite one carrying
//! the boundary radiance (Fig. 2, the wrap-around; 0 after the first order). Within a cell
//! the ray's path is h sqrt(1 + a^2 + b^2), and cell coverage is exact: path x cross-section
//! = h^3, so T = the ray's mean radiance over its path is the cell's mean radiance in the bin.
//!
//! Departures from the paper: T is the exact mean of L over the segment (for constant
//! sigma_t and source U in the cell: the integral of Eq. 3's solution), not Eq. 6's
//! L (1 - e^{-sigma_s dl}); with it a non-absorbing medium conserves energy cell by cell.

use glam::Vec3;

use super::directions::{face_axes, Direction};
use super::grid::LpmGrid;

/// One ray segment through a cell of constant sigma_t with source q (radiance per metre):
/// (radiance leaving, mean radiance along the path). Series where sigma_t dl is small (the
/// closed forms cancel catastrophically).
#[inline]
pub fn segment(l_in: Vec3, q: Vec3, sigma_t: Vec3, dl: f32) -> (Vec3, Vec3) {
    if sigma_t == Vec3::ZERO {
        // An empty cell: the thin-cell series at optical depth 0, the same values without the
        // exponential and the selects (a plume's box is mostly empty).
        return (l_in + q * dl, (l_in * dl + q * (dl * dl * 0.5)) / dl);
    }
    // The exponential and the divisions are most of a sweep's time: a grey cell (the usual
    // case) takes one of each for all three channels.
    let inv_dl = 1.0 / dl;
    if sigma_t.x == sigma_t.y && sigma_t.x == sigma_t.z {
        let (e, f1, f2) = coefficients(sigma_t.x, dl);
        return (l_in * e + q * f1, (l_in * f1 + q * f2) * inv_dl);
    }
    let c = [coefficients(sigma_t.x, dl), coefficients(sigma_t.y, dl), coefficients(sigma_t.z, dl)];
    let (e, f1, f2) = (Vec3::new(c[0].0, c[1].0, c[2].0), Vec3::new(c[0].1, c[1].1, c[2].1), Vec3::new(c[0].2, c[1].2, c[2].2));
    (l_in * e + q * f1, (l_in * f1 + q * f2) * inv_dl)
}

/// A segment's coefficients for one channel: e^{-sigma dl}, f1 = integral_0^dl e^{-sigma s} ds
/// and f2 = (dl - f1) / sigma, by their series where sigma dl is at most 1e-3.
#[inline]
fn coefficients(sigma: f32, dl: f32) -> (f32, f32, f32) {
    let od = sigma * dl;
    let e = if od == 0.0 { 1.0 } else { (-od).exp() };
    if od > 1e-3 {
        let inv = 1.0 / sigma;
        let f1 = (1.0 - e) * inv;
        (e, f1, (dl - f1) * inv)
    } else {
        (e, dl * (1.0 - od * 0.5 + od * od / 6.0), dl * dl * (0.5 - od / 6.0 + od * od / 24.0))
    }
}

/// The lateral shift of the map from layer w - 1 to layer w for slope `a`.
#[inline]
pub fn shift(a: f32, w: usize) -> i32 {
    (a * w as f32).round() as i32 - (a * (w as f32 - 1.0)).round() as i32
}

/// Sweep context of one face: the grid's extents in the face's (u, v, w) axes.
pub struct FaceFrame {
    pub face: usize,
    pub axes: (usize, usize, usize),
    pub nu: usize,
    pub nv: usize,
    pub nw: usize,
    pub forward: bool,
}

impl FaceFrame {
    pub fn new(grid: &LpmGrid, face: usize) -> Self {
        FaceFrame::from_dims(grid.dims, face)
    }

    pub fn from_dims(dims: [usize; 3], face: usize) -> Self {
        let axes = face_axes(face);
        FaceFrame { face, axes, nu: dims[axes.0], nv: dims[axes.1], nw: dims[axes.2], forward: face.is_multiple_of(2) }
    }

    /// Grid coordinates of map cell (u, v) at sweep layer `w` (0 = the face the rays enter).
    #[inline]
    pub fn cell(&self, u: usize, v: usize, w: usize) -> [usize; 3] {
        let mut c = [0usize; 3];
        c[self.axes.0] = u;
        c[self.axes.1] = v;
        c[self.axes.2] = if self.forward { w } else { self.nw - 1 - w };
        c
    }

    pub fn map_len(&self) -> usize {
        self.nu * self.nv
    }
}

/// Moves every ray of `map` from layer w - 1 to layer w; rays that wrap re-enter with
/// `boundary`. In place: the iteration runs against the shift so that no source is
/// overwritten before it is read.
fn shift_map(map: &mut [Vec3], nu: usize, nv: usize, du: i32, dv: i32, boundary: Vec3) {
    if du == 0 && dv == 0 {
        return;
    }
    for vi in 0..nv {
        let v = if dv > 0 { nv - 1 - vi } else { vi };
        for ui in 0..nu {
            let u = if du > 0 { nu - 1 - ui } else { ui };
            let (su, sv) = (u as i32 - du, v as i32 - dv);
            map[v * nu + u] = if su < 0 || sv < 0 || su >= nu as i32 || sv >= nv as i32 { boundary } else { map[sv as usize * nu + su as usize] };
        }
    }
}

/// A run of layers of a face's cells in the map's order (layer after layer, k = v nu + u
/// within): sigma_t, and U of the previous order in each storage bin the face's directions read
/// (`bins`, `bins.len()` values per cell). Gathered once for all the face's directions: read
/// straight from the grid, a face whose map runs across the grid's rows made every direction
/// load a cache line per cell.
pub struct Layers {
    pub bins: Vec<usize>,
    map_len: usize,
    pub sigma_t: Vec<Vec3>,
    pub source: Vec<Vec3>,
}

impl Layers {
    /// Empty buffers with room for `cells` cells of `bins` bins each: a solve allocates them
    /// once, for its largest face, and `reset`s them for each face.
    pub fn with_capacity(cells: usize, bins: usize) -> Self {
        Layers { bins: Vec::with_capacity(bins), map_len: 0, sigma_t: Vec::with_capacity(cells), source: Vec::with_capacity(cells * bins) }
    }

    /// Makes the buffers hold runs of up to `layers` layers of a map of `map_len` cells, and
    /// the storage bins of the face's directions `dirs`: within their capacity when it is
    /// enough.
    pub fn reset(&mut self, dirs: &[Direction], map_len: usize, layers: usize) {
        super::directions::storage_bins(dirs, &mut self.bins);
        self.map_len = map_len;
        self.sigma_t.resize(map_len * layers, Vec3::ZERO);
        self.source.resize(map_len * layers * self.bins.len(), Vec3::ZERO);
    }

    /// Bytes the buffers hold (their capacities).
    pub fn bytes(&self) -> u64 {
        ((self.sigma_t.capacity() + self.source.capacity()) * std::mem::size_of::<Vec3>()) as u64
    }

    /// Where direction `dir`'s source is: its bin's index among `bins`.
    pub fn slot(&self, dir: &Direction) -> usize {
        self.bins.binary_search(&dir.storage).expect("a face's directions' bins are gathered")
    }

    /// Fills the buffers from sweep layers `ws` of `ff`, rows in parallel where `parallel`.
    /// `u_prev` is U of the previous order, m values a cell.
    pub fn gather(&mut self, grid: &LpmGrid, ff: &FaceFrame, ws: std::ops::Range<usize>, m: usize, u_prev: &[Vec3], parallel: bool) {
        let nb = self.bins.len();
        let bins = &self.bins;
        let cells = ws.len() * self.map_len;
        super::stream::for_each_chunk(parallel, &mut self.sigma_t[..cells], ff.nu, Some(&mut self.source[..cells * nb]), ff.nu * nb, |r, sig, src| {
            let src = src.expect("sources for every row");
            let (w, v) = (ws.start + r / ff.nv, r % ff.nv);
            for u in 0..ff.nu {
                let idx = grid.index(ff.cell(u, v, w));
                sig[u] = grid.sigma_t[idx];
                for (b, &d) in bins.iter().enumerate() {
                    src[u * nb + b] = u_prev[idx * m + d];
                }
            }
        });
    }

    /// Layer `i` of the run: its sigma_t, and its sources (`bins.len()` a cell).
    fn layer(&self, i: usize) -> (&[Vec3], &[Vec3]) {
        let (n, nb) = (self.map_len, self.bins.len());
        (&self.sigma_t[i * n..(i + 1) * n], &self.source[i * n * nb..(i + 1) * n * nb])
    }
}

/// Moves direction `dir`'s map through the sweep layers `ws` of `ff` (gathered in `layers`;
/// `slot` its source's index there): `map` holds the rays leaving layer ws.start - 1 (ignored
/// at 0, where the rays enter with `boundary`), and on return those leaving the run's last
/// layer. `t` gets the mean radiance of each of the run's cells, layer after layer, in the
/// map's order.
#[allow(clippy::too_many_arguments)]
pub fn propagate_layers(ff: &FaceFrame, h: f32, dir: &Direction, layers: &Layers, slot: usize, boundary: Vec3, map: &mut [Vec3], ws: std::ops::Range<usize>, t: &mut [Vec3]) {
    let (nu, nv) = (ff.nu, ff.nv);
    let dl = h * (1.0 + dir.a * dir.a + dir.b * dir.b).sqrt();
    let nb = layers.bins.len();
    for (i, w) in ws.enumerate() {
        if w == 0 {
            map.fill(boundary);
        } else {
            shift_map(map, nu, nv, shift(dir.a, w), shift(dir.b, w), boundary);
        }
        let (sigma_t, source) = layers.layer(i);
        let out = &mut t[i * nu * nv..(i + 1) * nu * nv];
        for (k, ((l, mean), &sigma)) in map.iter_mut().zip(out.iter_mut()).zip(sigma_t).enumerate() {
            let (o, m) = segment(*l, source[k * nb + slot], sigma, dl);
            *l = o;
            *mean = m;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 3 against the transfer equation's closed form: a ray of radiance 2 through a cell
    /// of sigma_t 3 with source 1.5 over 0.4 m leaves with 2 e^{-1.2} + 0.5 (1 - e^{-1.2});
    /// the mean is the integral over the path / 0.4 (checked by a 10^4-step midpoint sum);
    /// the thin-cell series joins the closed form.
    #[test]
    fn segment_solves_the_transfer_equation() {
        let (out, mean) = segment(Vec3::splat(2.0), Vec3::splat(1.5), Vec3::splat(3.0), 0.4);
        let e = (-1.2f32).exp();
        assert!((out.x - (2.0 * e + 0.5 * (1.0 - e))).abs() < 1e-5);
        let n = 10_000;
        let sum: f32 = (0..n)
            .map(|i| {
                let s = (i as f32 + 0.5) * 0.4 / n as f32;
                2.0 * (-3.0 * s).exp() + 0.5 * (1.0 - (-3.0 * s).exp())
            })
            .sum::<f32>()
            / n as f32;
        assert!((mean.x - sum).abs() < 1e-4, "{} vs {sum}", mean.x);
        for od in [0.9e-3f32, 1.1e-3] {
            let (o, m) = segment(Vec3::ONE, Vec3::splat(0.7), Vec3::splat(od), 1.0);
            let exact_out = (-od).exp() as f64 + 0.7 * (1.0 - (-od as f64).exp()) / od as f64;
            assert!((o.x as f64 - exact_out).abs() < 1e-5, "od {od}");
            assert!(m.x > 1.0 - od && m.x < 1.0 + 0.7, "od {od}: {}", m.x);
        }
    }

    /// Every cell of every layer is visited by exactly one ray (the map shifts as a whole):
    /// the shifts over a sweep add up to round(a (n - 1)).
    #[test]
    fn shifts_add_up_to_the_slope() {
        for a in [-0.9f32, -0.5, -0.1, 0.0, 0.3, 0.7] {
            let total: i32 = (1..40).map(|w| shift(a, w)).sum();
            assert_eq!(total, (a * 39.0).round() as i32, "a {a}");
            assert!((1..40).all(|w| shift(a, w).abs() <= 1));
        }
    }
}
