//! The output (Sec. 4, done on a grid instead of camera-facing splats, as every solver here
//! returns S on a grid): each particle's scattered radiance towards the viewer, sum_d P[view,
//! d] I[p, d] (the same normalised HG row as the network's), splatted to the grid by a kernel
//! that is Gaussian in space (sigma = `kernel_radius` x the particle's ball radius) and in
//! density (a grid point takes its light from particles of similar density, so the lit rim's
//! light does not bleed into a dense core: the joint-bilateral idea of pop's upsample.rs, here
//! from scattered particles instead of a coarse grid), normalised by the weights, times
//! sigma_s(x).

use glam::Vec3;
use rayon::prelude::*;

use super::directions::phase_row;
use super::particles::Particles;
use crate::medium::Medium;
use crate::stages::ScatteringGrid;

/// The kernel is cut at 3 sigma, and at this many grid cells either side (a particle alone in
/// thin medium has a large ball; beyond this its light is left to nearer particles).
const MAX_HALF_EXTENT: i32 = 24;

/// Each particle's scattered radiance towards `camera` (RGB, before sigma_s).
pub fn towards_viewer(p: &Particles, radiance: &[Vec3], dirs: &[Vec3], g: f32, camera: Vec3) -> Vec<Vec3> {
    let d = dirs.len();
    (0..p.len())
        .map(|i| {
            let out = (camera - p.position[i]).normalize_or(Vec3::Z);
            phase_row(dirs, out, g).iter().zip(&radiance[i * d..(i + 1) * d]).map(|(&w, &l)| l * w).sum()
        })
        .collect()
}

/// A particle's kernel: the grid points it reaches (inclusive index box) and 1 / (2 sigma^2).
#[derive(Clone, Copy, Debug)]
pub struct Footprint {
    pub lo: glam::IVec3,
    pub hi: glam::IVec3,
    pub inv_spatial: f32,
}

/// What the accumulation over particles reads besides them (the part a GPU backend ports).
pub struct SplatPrep {
    /// Unscaled density at every grid point (0 outside the medium: such points take nothing).
    pub dens: Vec<f32>,
    /// 1 / (2 (range_sigma x the largest density)^2).
    pub inv_range: f32,
    pub footprints: Vec<Footprint>,
}

pub fn prepare(grid: &ScatteringGrid, medium: &Medium, p: &Particles, kernel_radius: f32, range_sigma: f32) -> SplatPrep {
    let [nx, ny, nz] = grid.dims;
    let dens: Vec<f32> = (0..grid.len())
        .map(|c| {
            let c = c as u32;
            medium.density_world(grid.position(c % nx, (c / nx) % ny, c / (nx * ny)))
        })
        .collect();
    let max_density = dens.iter().fold(0.0f32, |m, &v| m.max(v)).max(1e-12);
    let inv_range = 1.0 / (2.0 * (range_sigma * max_density).powi(2));
    let to_grid = grid.index_to_world.inverse();
    let m = grid.index_to_world.matrix3;
    let spacing = m.x_axis.length().min(m.y_axis.length()).min(m.z_axis.length());
    let footprints = p
        .position
        .iter()
        .zip(&p.radius)
        .map(|(&x, &radius)| {
            let sigma = kernel_radius * radius;
            let q = to_grid.transform_point3(x);
            let half = ((3.0 * sigma / spacing).ceil() as i32).clamp(1, MAX_HALF_EXTENT);
            Footprint {
                lo: (q.round().as_ivec3() - half).max(glam::IVec3::ZERO),
                hi: (q.round().as_ivec3() + half).min(glam::IVec3::new(nx as i32 - 1, ny as i32 - 1, nz as i32 - 1)),
                inv_spatial: 1.0 / (2.0 * sigma * sigma),
            }
        })
        .collect();
    SplatPrep { dens, inv_range, footprints }
}

/// Per grid point, the kernel-weighted sum of `values` and the sum of the weights, particles
/// in index order. One z-plane a task, each taking the particles that reach it in index order:
/// every point sums the same terms in the same order as one thread would (the same bits) on
/// every core.
pub fn accumulate(grid: &ScatteringGrid, p: &Particles, values: &[Vec3], prep: &SplatPrep) -> (Vec<Vec3>, Vec<f32>) {
    let dens = &prep.dens;
    let plane = grid.dims[0] as usize * grid.dims[1] as usize;
    let mut num = vec![Vec3::ZERO; grid.len()];
    let mut den = vec![0.0f32; grid.len()];
    num.par_chunks_mut(plane.max(1)).zip(den.par_chunks_mut(plane.max(1))).enumerate().for_each(|(k, (num, den))| {
        let k = k as i32;
        let first = k as usize * plane;
        for (i, (&x, &value)) in p.position.iter().zip(values).enumerate() {
            let Footprint { lo, hi, inv_spatial } = prep.footprints[i];
            if k < lo.z || k > hi.z {
                continue;
            }
            for j in lo.y..=hi.y {
                for ii in lo.x..=hi.x {
                    let c = grid.index(ii as u32, j as u32, k as u32);
                    if dens[c] <= 0.0 {
                        continue;
                    }
                    let ds = (grid.position(ii as u32, j as u32, k as u32) - x).length_squared();
                    let dr = dens[c] - p.density[i];
                    let w = (-ds * inv_spatial - dr * dr * prep.inv_range).exp();
                    num[c - first] += value * w;
                    den[c - first] += w;
                }
            }
        }
    });
    (num, den)
}

/// Adds sigma_s x the weighted mean (`num` / `den`) into `grid` at every point inside the
/// medium; a point no kernel reaches takes its nearest particle's value. Points in parallel:
/// each is its own sum.
pub fn finish(grid: &mut ScatteringGrid, medium: &Medium, p: &Particles, values: &[Vec3], dens: &[f32], num: &[Vec3], den: &[f32]) {
    let [nx, ny, _] = grid.dims;
    let positions = |c: usize| {
        let cu = c as u32;
        (cu % nx, (cu / nx) % ny, cu / (nx * ny))
    };
    let to_world = grid.index_to_world;
    grid.data.par_iter_mut().enumerate().for_each(|(c, out)| {
        if dens[c] <= 0.0 {
            return;
        }
        let mean = if den[c] > 1e-20 {
            num[c] / den[c]
        } else {
            let (i, j, k) = positions(c);
            let x = to_world.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
            let nearest = (0..p.len()).min_by(|&a, &b| (p.position[a] - x).length_squared().total_cmp(&(p.position[b] - x).length_squared()));
            nearest.map_or(Vec3::ZERO, |n| values[n])
        };
        *out += medium.sigma_s(dens[c]) * mean;
    });
}

/// sigma_s(x) x the kernel-weighted mean of `values` at every point of `grid` inside the
/// medium, added to `grid`. A point no kernel reaches takes its nearest particle's value.
pub fn splat_into(grid: &mut ScatteringGrid, medium: &Medium, p: &Particles, values: &[Vec3], kernel_radius: f32, range_sigma: f32) {
    let prep = prepare(grid, medium, p, kernel_radius, range_sigma);
    let (num, den) = accumulate(grid, p, values, &prep);
    finish(grid, medium, p, values, &prep.dens, &num, &den);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solvers::testing::fixture_scene;

    /// The splat's sums by z-plane on every core are the one-thread loop over particles, bit for
    /// bit (a session frame must equal its one-off solve on any number of threads): checked on
    /// the plume fixture's particles against that loop, kept here.
    #[test]
    fn network_splat_by_planes_is_the_one_thread_sum() {
        let medium = fixture_scene("plume").medium;
        let p = super::super::particles::sample(&medium, 3000, 7);
        let grid = ScatteringGrid::over_medium(&medium, 40).unwrap();
        let values: Vec<Vec3> = (0..p.len()).map(|i| Vec3::new(1.0 + (i % 7) as f32, 0.5 + (i % 3) as f32, 0.1 * (i % 11) as f32)).collect();
        let prep = prepare(&grid, &medium, &p, 1.5, 0.25);
        let (num, den) = accumulate(&grid, &p, &values, &prep);
        let (mut num1, mut den1) = (vec![Vec3::ZERO; grid.len()], vec![0.0f32; grid.len()]);
        for (i, (&x, &value)) in p.position.iter().zip(&values).enumerate() {
            let Footprint { lo, hi, inv_spatial } = prep.footprints[i];
            for k in lo.z..=hi.z {
                for j in lo.y..=hi.y {
                    for ii in lo.x..=hi.x {
                        let c = grid.index(ii as u32, j as u32, k as u32);
                        if prep.dens[c] <= 0.0 {
                            continue;
                        }
                        let ds = (grid.position(ii as u32, j as u32, k as u32) - x).length_squared();
                        let dr = prep.dens[c] - p.density[i];
                        let w = (-ds * inv_spatial - dr * dr * prep.inv_range).exp();
                        num1[c] += value * w;
                        den1[c] += w;
                    }
                }
            }
        }
        assert!(den.iter().filter(|w| **w > 0.0).count() > 1000, "the kernels reach the grid");
        assert!(num.iter().zip(&num1).all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)));
        assert!(den.iter().zip(&den1).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}
