//! Coarse grid of density maxima for delta / ratio tracking, traversed by a 3D DDA in index
//! space. A per-cell majorant (instead of one global maximum) keeps the number of null
//! collisions low in sparse smoke, where the global maximum is far above the typical density.

use glam::{IVec3, Vec3};

use super::Medium;

#[derive(Clone, Debug)]
pub struct MajorantGrid {
    /// Index-space position of the grid's minimum corner.
    origin: Vec3,
    /// Cell edge in voxels.
    cell: f32,
    dims: IVec3,
    /// Maximum *scaled* extinction (max over RGB channels) in each cell, 1/m.
    values: Vec<f32>,
}

/// One piece of a ray inside one majorant cell: parameter range and majorant.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    pub t0: f32,
    pub t1: f32,
    pub majorant: f32,
}

impl MajorantGrid {
    /// `max_cells_per_axis` bounds the grid (e.g. 64). Cells are cubes in index space.
    pub fn new(medium: &Medium, max_cells_per_axis: i32) -> Self {
        let scale = medium.density_scale.max_element().max(0.0);
        if medium.grid.is_empty() {
            return MajorantGrid { origin: Vec3::ZERO, cell: 1.0, dims: IVec3::ZERO, values: Vec::new() };
        }
        let (lo, hi) = medium.index_bounds();
        let extent = hi - lo;
        let cell = (extent.max_element() / max_cells_per_axis as f32).max(1.0).ceil();
        let dims = (extent / cell).ceil().as_ivec3().max(IVec3::ONE);
        let mut values = vec![0.0f32; (dims.x * dims.y * dims.z) as usize];
        use rayon::prelude::*;
        values.par_chunks_mut((dims.x * dims.y) as usize).enumerate().for_each(|(z, slab)| {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    let c = IVec3::new(x, y, z as i32);
                    let clo = lo + c.as_vec3() * cell;
                    let chi = clo + Vec3::splat(cell);
                    // Every voxel whose trilinear support touches the cell.
                    let vlo = clo.floor().as_ivec3();
                    let vhi = chi.ceil().as_ivec3();
                    slab[(x + dims.x * y) as usize] = medium.grid.max_in_box(vlo, vhi) * scale;
                }
            }
        });
        MajorantGrid { origin: lo, cell, dims, values }
    }

    /// The grid as stored, for a GPU port of `traverse` (volscatter-gpu photon_grid): its
    /// minimum corner in index space, cell edge in voxels, cells per axis and values (x fastest).
    pub fn storage(&self) -> (Vec3, f32, IVec3, &[f32]) {
        (self.origin, self.cell, self.dims, &self.values)
    }

    pub fn max(&self) -> f32 {
        self.values.iter().fold(0.0, |m, &v| m.max(v))
    }

    /// Visits the segments of the index-space ray `o + t d` for t in [t_min, t_max] in order.
    /// `visit` returns false to stop.
    pub fn traverse(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32, mut visit: impl FnMut(Segment) -> bool) {
        if self.values.is_empty() {
            return;
        }
        let gmin = self.origin;
        let gmax = self.origin + self.dims.as_vec3() * self.cell;
        // Slab test.
        let inv = d.recip();
        let ta = (gmin - o) * inv;
        let tb = (gmax - o) * inv;
        let tnear = ta.min(tb);
        let tfar = ta.max(tb);
        // NaN (0 * inf) components mean the ray is parallel to and on a slab boundary: ignore them.
        let pick_max = |v: Vec3| [v.x, v.y, v.z].into_iter().filter(|x| !x.is_nan()).fold(f32::NEG_INFINITY, f32::max);
        let pick_min = |v: Vec3| [v.x, v.y, v.z].into_iter().filter(|x| !x.is_nan()).fold(f32::INFINITY, f32::min);
        let mut t = t_min.max(pick_max(tnear));
        let t_end = t_max.min(pick_min(tfar));
        // NaN (a degenerate ray) counts as empty, like t >= t_end.
        if t.partial_cmp(&t_end) != Some(std::cmp::Ordering::Less) {
            return;
        }
        let p = (o + d * t - gmin) / self.cell;
        let mut c = p.floor().as_ivec3().clamp(IVec3::ZERO, self.dims - IVec3::ONE);
        let step = IVec3::new(
            if d.x > 0.0 { 1 } else { -1 },
            if d.y > 0.0 { 1 } else { -1 },
            if d.z > 0.0 { 1 } else { -1 },
        );
        let next_boundary = |c: IVec3, axis: usize| -> f32 {
            let dc = d[axis];
            if dc == 0.0 {
                return f32::INFINITY;
            }
            let edge = gmin[axis] + (c[axis] + if dc > 0.0 { 1 } else { 0 }) as f32 * self.cell;
            (edge - o[axis]) / dc
        };
        let mut t_next = Vec3::new(next_boundary(c, 0), next_boundary(c, 1), next_boundary(c, 2));
        let t_delta = (Vec3::splat(self.cell) * inv).abs();
        loop {
            let axis = if t_next.x < t_next.y && t_next.x < t_next.z {
                0
            } else if t_next.y < t_next.z {
                1
            } else {
                2
            };
            let t1 = t_next[axis].min(t_end);
            let idx = (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize;
            if t1 > t && !visit(Segment { t0: t, t1, majorant: self.values[idx] }) {
                return;
            }
            if t_next[axis] >= t_end {
                return;
            }
            t = t1;
            c[axis] += step[axis];
            if c[axis] < 0 || c[axis] >= self.dims[axis] {
                return;
            }
            t_next[axis] += t_delta[axis];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::{DensityGrid, GridLimits};
    use glam::Affine3A;

    #[test]
    fn majorant_bounds_density_along_random_rays() {
        let n = 24;
        let vals: Vec<f32> = (0..n * n * n).map(|i| ((i * 37 % 101) as f32 / 100.0).powi(3)).collect();
        let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
        let m = Medium::new(grid, Affine3A::from_scale(Vec3::splat(0.1)), Vec3::splat(3.0), Vec3::ONE, 0.0);
        let maj = MajorantGrid::new(&m, 5);
        let mut rng = crate::rng::Rng::new(1, 2);
        for _ in 0..200 {
            let o = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 40.0 - 8.0;
            let d = crate::sampling::uniform_sphere(rng.pair());
            let mut last = 0.0f32;
            let mut covered = 0.0;
            maj.traverse(o, d, 0.0, 100.0, |s| {
                assert!(s.t0 >= last - 1e-4, "segments out of order");
                last = s.t1;
                covered += s.t1 - s.t0;
                for k in 0..=10 {
                    let t = s.t0 + (s.t1 - s.t0) * k as f32 / 10.0;
                    let dens = m.grid.sample(o + d * t) * 3.0;
                    assert!(dens <= s.majorant + 1e-5, "density {dens} above majorant {}", s.majorant);
                }
                true
            });
            assert!(covered <= 100.0);
        }
    }
}
