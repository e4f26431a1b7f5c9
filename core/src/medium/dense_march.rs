//! The density lookups of the hot deterministic marches: every VPL connection (vpl's
//! gather.rs `connect`), the compositor's shadow rays (single-scattering grid) and its camera
//! rays. The same midpoint quadrature as medium::optical_depth, made cheaper, since it is
//! nearly all of their time (perf on cube_g07, 8192 walks, 12-cell gather: optical_depth 78%
//! and the `floorf` calls of its trilinear lookups 12% of 15 s; on the default scene's vpl
//! render, optical_depth and floorf were 60% of the whole render through the compositor).
//!
//! What changes: the density is read from a dense copy of the grid (zero-padded by two
//! voxels, so that no lookup needs a bounds test or a brick table), the ray is carried into
//! index space once (not each sample through the world-to-index map), the lattice cell is
//! found by truncation of non-negative coordinates (floor without a libm call), and the march
//! stops once the optical depth passes `OPAQUE` (the transmittance below e^-64, 1.6e-28,
//! nothing at f32 next to any other connection). The samples are the same points, so the
//! optical depth equals optical_depth's up to float rounding (tests below: 1e-5 relative).
//! A grid whose dense copy the memory budget refuses keeps the sparse lookup.

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use crate::medium::trilinear::trilinear_cell;
use crate::medium::{optical_depth, ray_box, Medium};

/// Optical depth (in the largest channel) past which the march stops.
const OPAQUE: f32 = 64.0;

/// Largest dense copy (voxels, padding included): 64 MiB, copied in ~50 ms on two cores, so a
/// solve's cancellation is not held up by it (it has no cancellation point of its own).
const MAX_DENSE: u64 = 1 << 24;

/// Padding of the dense copy, in voxels on every side: the trilinear ramp outside the stored
/// voxels is one voxel, and a clamped cell two voxels out reads zeros only.
const PAD: i32 = 2;

pub struct Marcher<'a> {
    medium: &'a Medium,
    /// Dense density over the grid's box grown by PAD (x fastest), None: sparse lookups.
    dense: Option<Vec<f32>>,
    /// What lattice coordinates are offset from the medium's index space: the index of the
    /// dense array's first voxel with the dense copy, zero without.
    offset: Vec3,
    dims: IVec3,
    /// The medium's world box (rays are clipped to it, as optical_depth does).
    bounds: (Vec3, Vec3),
    /// OPAQUE in units of the unscaled density integral (largest channel's scale).
    opaque: f32,
}

impl<'a> Marcher<'a> {
    pub fn new(medium: &'a Medium) -> Self {
        Self::for_lookups(medium, u64::MAX)
    }

    /// `new` for a caller that will make about `lookups` density lookups: the dense copy is
    /// made only when they are at least as many as its voxels (copying costs about a sparse
    /// lookup per voxel, and saves a fraction of one per lookup), so that a small image of a
    /// large medium (a thumbnail) does not pay more for the copy than for its march.
    pub fn for_lookups(medium: &'a Medium, lookups: u64) -> Self {
        let (lo, hi) = medium.grid.bbox();
        let origin = lo - IVec3::splat(PAD);
        let dims = hi - lo + IVec3::splat(1 + 2 * PAD);
        let count = dims.x.max(0) as u64 * dims.y.max(0) as u64 * dims.z.max(0) as u64;
        let wanted = !medium.grid.is_empty() && count <= MAX_DENSE && lookups >= count && crate::budget::check_elements::<f32>("dense density copy", count).is_ok();
        let dense = wanted.then(|| {
            let mut data = vec![0.0f32; count as usize];
            data.par_chunks_mut((dims.x * dims.y) as usize).enumerate().for_each(|(z, slab)| {
                for (o, v) in slab.iter_mut().enumerate() {
                    let (x, y) = (o as i32 % dims.x, o as i32 / dims.x);
                    *v = medium.grid.voxel(origin + IVec3::new(x, y, z as i32));
                }
            });
            data
        });
        let scale = medium.density_scale.max_element();
        // Sparse lookups read the medium's own index space: no offset.
        let offset = if dense.is_some() { origin.as_vec3() } else { Vec3::ZERO };
        Marcher { medium, dense, offset, dims, bounds: medium.world_bounds(), opaque: if scale > 0.0 { OPAQUE / scale } else { f32::INFINITY } }
    }

    /// Whether the density was copied (false: the memory budget or MAX_DENSE refused it, and
    /// lookups go through the sparse grid).
    pub fn is_dense(&self) -> bool {
        self.dense.is_some()
    }

    /// The ray `x + t d` (world) in this marcher's lattice coordinates (`density_lattice`'s):
    /// the same `t` reaches the same point. For a caller that marches a ray with its own
    /// quadrature (the compositor's camera rays) and carries it into index space once.
    #[inline]
    pub fn lattice_ray(&self, x: Vec3, d: Vec3) -> (Vec3, Vec3) {
        let w2i = &self.medium.world_to_index;
        (w2i.transform_point3(x) - self.offset, w2i.transform_vector3(d))
    }

    /// Unscaled density at `p` in lattice coordinates (`lattice_ray`), anywhere (zero outside
    /// the medium's box): the medium's trilinear lookup, up to the float rounding of the
    /// lattice coordinates.
    #[inline]
    pub fn density_lattice(&self, p: Vec3) -> f32 {
        match &self.dense {
            Some(data) => self.dense_at(data, p),
            None => self.medium.grid.sample(p),
        }
    }

    /// Trilinear lookup in the dense copy at lattice coordinates `p`.
    #[inline(always)]
    fn dense_at(&self, data: &[f32], p: Vec3) -> f32 {
        let dims = self.dims;
        // Truncation is floor for p >= 0; below 0 or past the far side the clamped cell lies
        // in the zero padding (both corners on that axis zero), as the sparse grid reads.
        // Callers pass finite points (samples of rays clipped to the medium's box).
        let c = p.max(Vec3::ZERO).as_ivec3().min(dims - IVec3::splat(2));
        trilinear_cell(c, p - c.as_vec3(), |c: IVec3| data[(c.x + dims.x * (c.y + dims.y * c.z)) as usize])
    }

    pub fn medium(&self) -> &'a Medium {
        self.medium
    }

    /// Optical depth (RGB) from `x` along unit `d` over at most `t_max`: optical_depth's
    /// midpoint quadrature with at most `max_steps` steps of at least `min_step`.
    pub fn optical_depth(&self, x: Vec3, d: Vec3, t_max: f32, min_step: f32, max_steps: u32) -> Vec3 {
        let Some(data) = &self.dense else { return optical_depth(self.medium, x, d, t_max, min_step, max_steps) };
        let Some((t0, t1)) = ray_box(x, d, self.bounds.0, self.bounds.1) else { return Vec3::ZERO };
        let t1 = t1.min(t_max);
        if t1 <= t0 {
            return Vec3::ZERO;
        }
        let n = (((t1 - t0) / min_step).ceil() as u32).clamp(1, max_steps);
        let h = (t1 - t0) / n as f32;
        // The ray in the dense array's lattice coordinates.
        let (start, dir) = self.lattice_ray(x, d);
        let mut tau = 0.0f32;
        for i in 0..n {
            tau += self.dense_at(data, start + dir * (t0 + (i as f32 + 0.5) * h));
            if tau * h > self.opaque {
                break;
            }
        }
        self.medium.density_scale * tau * h
    }

    /// The unscaled density integral from `x` along unit `d` at the nodes 0, h, 2h, ... up to
    /// where the ray leaves the medium's box, appended to `out` (at least one node, 0): the
    /// midpoint quadrature of `optical_depth` with steps h of at most `min_step` (at most
    /// `max_steps` of them). Returns h (0 when the ray misses the box). Past OPAQUE the
    /// remaining nodes are not marched: they hold the last value (vpl's depth_map.rs).
    pub fn depth_profile(&self, x: Vec3, d: Vec3, min_step: f32, max_steps: u32, out: &mut Vec<f32>) -> f32 {
        out.push(0.0);
        let Some((_, t1)) = ray_box(x, d, self.bounds.0, self.bounds.1) else { return 0.0 };
        let n = ((t1 / min_step).ceil() as u32).clamp(1, max_steps);
        let h = t1 / n as f32;
        let (start, dir) = self.lattice_ray(x, d);
        let mut tau = 0.0f32;
        for i in 0..n {
            if tau * h <= self.opaque {
                tau += self.density_lattice(start + dir * ((i as f32 + 0.5) * h));
            }
            out.push(tau * h);
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plume fixture's medium in a rotated frame (the sparse grid's bounds and ramps, and a
    /// world-to-index map that is not axis-aligned).
    fn rotated_plume() -> Medium {
        let p = crate::solvers::testing::fixture_scene("plume").medium;
        Medium::new(p.grid.clone(), glam::Affine3A::from_rotation_z(0.4) * p.index_to_world, p.density_scale, p.albedo, p.g)
    }

    /// The dense march gives optical_depth's result on the plume (heterogeneous, a rotated
    /// and scaled frame: the sparse grid's bounds and ramps) for rays from inside and outside,
    /// to 5e-4 relative (measured 1.2e-4: the index-space ray's float rounding, ~1e-6 of a
    /// voxel, times the density's gradient, over small optical depths; plus 1e-6 absolute).
    #[test]
    fn dense_march_equals_optical_depth() {
        let m = &rotated_plume();
        let marcher = Marcher::new(m);
        assert!(marcher.dense.is_some());
        let (lo, hi) = m.world_bounds();
        let mut rng = crate::rng::Rng::new(7, 0);
        let mut worst = 0.0f32;
        for _ in 0..2000 {
            let x = lo + (hi - lo) * (Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1.4 - 0.2);
            let d = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize();
            let t = (hi - lo).length() * rng.f32();
            let want = optical_depth(m, x, d, t, 0.01, 1024);
            let got = marcher.optical_depth(x, d, t, 0.01, 1024);
            if want.max_element() < OPAQUE {
                worst = worst.max(((got - want).abs() / (want.abs() + 1e-6)).max_element());
            }
        }
        assert!(worst < 5e-4, "worst relative difference {worst}");
    }

    /// The lattice lookups (the compositor's camera march) read the medium's density, with the
    /// dense copy and without it (the fallback when the budget refuses the copy), at points in
    /// and around the plume's box along index-space rays: to 3e-6 of the largest density
    /// (the lattice ray's float rounding times the density's gradient; measured 1.1e-6 both).
    #[test]
    fn lattice_lookups_equal_density_world() {
        let m = &rotated_plume();
        let dense = Marcher::new(m);
        let mut sparse = Marcher::new(m);
        (sparse.dense, sparse.offset) = (None, Vec3::ZERO);
        assert!(dense.is_dense() && !sparse.is_dense());
        let (lo, hi) = m.world_bounds();
        let peak = (0..2000).fold(0.0f32, |a, i| a.max(m.density_world(lo + (hi - lo) * (i as f32 / 2000.0))));
        let mut rng = crate::rng::Rng::new(11, 0);
        let mut worst = [0.0f32; 2];
        for _ in 0..2000 {
            let o = lo + (hi - lo) * (Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1.4 - 0.2);
            let d = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize();
            let t = (hi - lo).length() * rng.f32();
            let want = m.density_world(o + d * t);
            for (k, marcher) in [&dense, &sparse].into_iter().enumerate() {
                let (start, dir) = marcher.lattice_ray(o, d);
                worst[k] = worst[k].max((marcher.density_lattice(start + dir * t) - want).abs() / peak);
            }
        }
        assert!(peak > 0.0 && worst[0] < 3e-6 && worst[1] < 3e-6, "worst difference / peak density: dense {}, sparse {}", worst[0], worst[1]);
    }
}
