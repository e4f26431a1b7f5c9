//! `near_upsample: ratio`: the near field of the gather's ball kernel corrected to the output
//! resolution's kernel, with the near light's level upsampled as a ratio to a density integral.
//!
//! Why: the gather takes each VPL's 1/d^2 with the ball kernel K_b of radius b ~ one gather
//! cell (`near_field: ball`): the same integral as 1/d^2 over space, but with the mass within
//! b moved out to ~b, where the transmittance is lower and the density around the point is
//! another. A finer gather (smaller b) is brighter on the point light beside the plume
//! (tests.rs); this stage gives an output point the light it would get with the output's own
//! ball K_a (a = one output cell), deterministically from the density.
//!
//! How: with the VPLs' power density sigma_t(y) phi(y), phi smooth over r_n (walks collide in
//! proportion to sigma_t), the expected light of kernel K at x is phi(x) times a density
//! integral of K, so the correction from K_b to K_a is
//!   J_a(x) - J_b(x) ~ phi(x) C(x),  C(x) = integral of rho(y) (K_a - K_b)(|x - y|) T dy,
//! T = exp(-sigma_t(x) |x - y|) a local transmittance. C is zero where the density is flat
//! and there is no attenuation (both kernels integrate like 1/d^2), positive where x sits in a
//! wisp denser than its surroundings or the medium attenuates over b. phi is estimated from
//! the near part of the gather, J_near (the VPLs within r_n = `near_radius` gather cells,
//! weighted by refine.rs's `near_weight`): at the coarse points J_near / D_b, D_b the same
//! density integral of w K_b T, and upsampled as the ratio of the filtered sums
//! sum w J_near / sum w D_b with pop's bilateral weights (no division by one coarse point's
//! small D). Then
//!   S(x) = S_up(x) + sigma_s(x) C(x) (sum w J_near / sum w D_b),
//! S_up the usual upsampling (`upsample_fit`), clamped at zero.
//!
//! C and D_b are sums over the output grid's points (the upsampling's own densities) within
//! r_n, each with its cell's volume; C is summed as the density's departure from rho(x) plus
//! rho(x) times the kernels' difference integrated over all space (`kernel_difference`,
//! tabulated over the density): exact where the density is flat, the density beyond r_n taken
//! as rho(x). J_near at the coarse points is gathered again on the CPU (refine.rs's hash of the
//! VPLs within r_n: a few per cent of the gather's connections), so the gather, on either
//! backend, is unchanged and the GPU needs no second accumulator.
//!
//! Measured: see `NearUpsample::Ratio` (settings.rs).

use glam::{Affine3A, IVec3, Vec3};
use rayon::prelude::*;

use super::gather::Kernel;
use super::march::Marcher;
use super::refine::{near_weight, Near};
use super::settings::{NearField, VplSettings};
use super::walks::Walks;
use crate::error::{Error, Result};
use crate::medium::{ball_mean_inverse_square, near_field_radius, Medium};
use crate::scene::Scene;
use crate::stages::upsample::{footprint, Merged};
use crate::stages::mip::MediumMip;
use crate::stages::upsample::Upsampling;
use crate::stages::upsample::Bilateral;
use crate::stages::{Progress, ScatteringGrid};

/// The density's near-field integral D, summed over the output grid's own points. Measured on
/// plume_point (4096 walks, 16-cell gather, 8 seeds): a lattice refined twice (the density at
/// half the output's spacing, 8x the taps) gave the same 8-seed flux to 4 digits (x0.8913), so
/// the correction is not limited by this quadrature.
struct DensityIntegral {
    /// Density at the output grid's points (the mip at the output's footprint; 0 outside).
    rho: Vec<f32>,
    /// The output grid's dims.
    dims: IVec3,
    frame: Affine3A,
    to_index: Affine3A,
    /// Volume of one output cell (each point's share of the integrals).
    volume: f32,
    /// Lattice offsets within r_n: (offset, distance).
    taps: Vec<(IVec3, f32)>,
    /// Half-extent of the taps' box in output cells, per axis.
    reach: IVec3,
    radius: f32,
    /// Smallest kernel radius: the ball of one output cell's volume.
    cell_ball: f32,
}

impl DensityIntegral {
    fn new(medium: &Medium, mip: &MediumMip, out: &ScatteringGrid, radius: f32, progress: &dyn Progress) -> Result<Self> {
        let (frame, fp) = (out.index_to_world, footprint(medium, out));
        let w2i = medium.world_to_index;
        let [nx, ny, nz] = out.dims;
        let mut rho = vec![0.0f32; (nx * ny * nz) as usize];
        rho.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, plane)| {
            if progress.cancelled() {
                return;
            }
            for (o, r) in plane.iter_mut().enumerate() {
                let x = frame.transform_point3(Vec3::new((o as u32 % nx) as f32, (o as u32 / nx) as f32, k as f32));
                *r = mip.sample(medium, w2i.transform_point3(x), fp).max(0.0);
            }
        });
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let m = frame.matrix3;
        let reach = IVec3::new((radius / m.x_axis.length()).ceil() as i32, (radius / m.y_axis.length()).ceil() as i32, (radius / m.z_axis.length()).ceil() as i32);
        let mut taps = Vec::new();
        for dz in -reach.z..=reach.z {
            for dy in -reach.y..=reach.y {
                for dx in -reach.x..=reach.x {
                    let o = IVec3::new(dx, dy, dz);
                    let d = (m * o.as_vec3()).length();
                    if d < radius {
                        taps.push((o, d));
                    }
                }
            }
        }
        let dims = IVec3::new(nx as i32, ny as i32, nz as i32);
        let volume = glam::Mat3::from(m).determinant().abs();
        Ok(DensityIntegral { rho, dims, frame, to_index: frame.inverse(), volume, taps, reach, radius, cell_ball: near_field_radius(&frame) })
    }

    /// The kernel K x T at distance d for a point of density `rho` using `kernel`.
    #[inline]
    fn weight(&self, d: f32, kernel: Kernel, sigma_t: f32) -> f32 {
        let k = match kernel {
            Kernel::Ball { radius: b, .. } | Kernel::Hat { radius: b, .. } => ball_mean_inverse_square(d, b.max(self.cell_ball)),
            Kernel::Clamp(r) => 1.0 / d.max(r.max(self.cell_ball)).powi(2),
        };
        k * (-sigma_t * d).exp()
    }

    #[inline]
    fn index(&self, c: IVec3) -> Option<usize> {
        (c.cmpge(IVec3::ZERO).all() && c.cmplt(self.dims).all()).then(|| (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize)
    }

    /// C at output point `c` of density `rho`: the density around it weighted by the fine kernel
    /// minus the gather's (`ball` its radius) and the local transmittance: the lattice sum of
    /// the density's departure from `rho` out to r_n, plus `rho` times the kernels' difference
    /// integrated over all space (`whole`, `kernel_difference`): exact quadrature where the
    /// density is flat, the density beyond r_n taken as `rho`.
    fn correction_at_lattice(&self, c: IVec3, ball: f32, sigma_t: f32, whole: impl Fn(f32) -> f32) -> f32 {
        let ball = ball.max(self.cell_ball);
        if ball <= self.cell_ball {
            return 0.0;
        }
        let Some(at) = self.index(c) else { return 0.0 };
        let rho = self.rho[at];
        let mut sum = 0.0;
        for &(o, d) in &self.taps {
            let r = self.index(c + o).map_or(0.0, |i| self.rho[i]);
            let k = ball_mean_inverse_square(d, self.cell_ball) - ball_mean_inverse_square(d, ball);
            sum += (r - rho) * self.volume * k * (-sigma_t * d).exp();
        }
        sum + rho * whole(rho)
    }

    /// D at any point `x` (world), over the output points within r_n.
    fn at(&self, x: Vec3, kernel: Kernel, sigma_t: f32) -> f32 {
        let q = self.to_index.transform_point3(x).round().as_ivec3();
        let mut sum = 0.0;
        for dz in -self.reach.z - 1..=self.reach.z + 1 {
            for dy in -self.reach.y - 1..=self.reach.y + 1 {
                for dx in -self.reach.x - 1..=self.reach.x + 1 {
                    let c = q + IVec3::new(dx, dy, dz);
                    let Some(i) = self.index(c) else { continue };
                    let r = self.rho[i];
                    if r <= 0.0 {
                        continue;
                    }
                    let d = (self.frame.transform_point3(c.as_vec3()) - x).length();
                    let w = near_weight(d, self.radius);
                    if w > 0.0 {
                        sum += r * w * self.volume * self.weight(d, kernel, sigma_t);
                    }
                }
            }
        }
        sum
    }
}

/// The integral over all space of (K_a - K_b)(|y|) exp(-sigma_t |y|) dy, K_r the ball kernel of
/// radius r (b > a): zero without attenuation (both kernels integrate like 1/d^2); with it, the
/// light the wider ball loses by moving its mass out to where the transmittance is lower.
/// Radial midpoint sums: uniform steps of b / 256 to 4 b, then steps growing by 2% to 10^4 b.
pub fn kernel_difference(a: f32, b: f32, sigma_t: f32) -> f32 {
    let f = |d: f32| (ball_mean_inverse_square(d, a) - ball_mean_inverse_square(d, b)) as f64 * (d as f64).powi(2) * (-(sigma_t as f64) * d as f64).exp();
    let mut sum = 0.0f64;
    let h = b / 256.0;
    for i in 0..1024 {
        sum += f((i as f32 + 0.5) * h) * h as f64;
    }
    let mut d = 4.0 * b;
    while d < 1e4 * b {
        let step = 0.02 * d;
        sum += f(d + 0.5 * step) * step as f64;
        d += step;
    }
    (4.0 * std::f64::consts::PI * sum) as f32
}

/// S on the output grid: `upsample` (`upsample_fit`) of the gathered J, plus the correction of
/// the gather's ball kernel to the output's, phi C, phi upsampled as a ratio (module doc).
/// Without the ball kernel (`near_field: clamp | compensate`) the kernels do not differ and S is
/// `upsample`'s. Ends with `Error::Cancelled` within a plane once `progress` is cancelled.
#[allow(clippy::too_many_arguments)]
pub fn upsample(
    scene: &Scene,
    mip: &MediumMip,
    walks: &Walks,
    merged: &Merged,
    settings: &VplSettings,
    pop_like: &Upsampling,
    progress: &dyn Progress,
    upsample: impl Fn(&Merged) -> Result<ScatteringGrid>,
) -> Result<ScatteringGrid> {
    let mut s = upsample(merged)?;
    if settings.near_field != NearField::Ball {
        return Ok(s);
    }
    let medium = &scene.medium;
    let frame = merged.j.index_to_world;
    let march = Marcher::new(medium);
    let near = Near::new(scene, &march, walks, &frame, settings.near_radius, settings);
    let j_near = near.at_coarse(merged, progress)?;
    let dens = DensityIntegral::new(medium, mip, &s, near.radius(), progress)?;
    let sigma_t = |rho: f32| medium.sigma_t(rho).max_element();
    let ball = |rho: f32| match near.kernel(rho).0 {
        Kernel::Ball { radius: b, .. } | Kernel::Hat { radius: b, .. } => b,
        Kernel::Clamp(_) => 0.0,
    };
    // D at the coarse points where the gather ran, with their kernel.
    let [cx, cy, _] = merged.j.dims;
    let mut d_coarse = vec![0.0f32; merged.density.len()];
    d_coarse.par_chunks_mut((cx * cy) as usize).enumerate().for_each(|(k, plane)| {
        if progress.cancelled() {
            return;
        }
        for (o, d) in plane.iter_mut().enumerate() {
            let rho = merged.density[k * (cx * cy) as usize + o];
            if rho > 0.0 {
                let x = frame.transform_point3(Vec3::new((o as u32 % cx) as f32, (o as u32 / cx) as f32, k as f32));
                *d = dens.at(x, near.kernel(rho).0, sigma_t(rho));
            }
        }
    });
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    // kernel_difference as a function of the two densities it depends on: the coarse
    // neighbours' (the gather's ball radius follows theirs, `mean_free_paths`) and the point's
    // own (the local transmittance), tabulated and interpolated bilinearly.
    let rho_max = dens.rho.iter().chain(&merged.density).fold(0.0f32, |m, &r| m.max(r)).max(1e-12);
    const TABLE: usize = 64;
    let table: Vec<f32> = (0..(TABLE + 1) * (TABLE + 1))
        .into_par_iter()
        .map(|n| {
            let (gi, li) = (n / (TABLE + 1), n % (TABLE + 1));
            let b = ball(rho_max * gi as f32 / TABLE as f32).max(dens.cell_ball);
            if b <= dens.cell_ball { 0.0 } else { kernel_difference(dens.cell_ball, b, sigma_t(rho_max * li as f32 / TABLE as f32)) }
        })
        .collect();
    let whole = |guide: f32, rho: f32| {
        let cell = |v: f32| {
            let t = (v / rho_max).clamp(0.0, 1.0) * TABLE as f32;
            let i = (t as usize).min(TABLE - 1);
            (i, t - i as f32)
        };
        let ((g, fg), (l, fl)) = (cell(guide), cell(rho));
        let at = |g: usize, l: usize| table[g * (TABLE + 1) + l];
        let lo = at(g, l) + (at(g, l + 1) - at(g, l)) * fl;
        let hi = at(g + 1, l) + (at(g + 1, l + 1) - at(g + 1, l)) * fl;
        lo + (hi - lo) * fg
    };
    let filter = Bilateral::new(merged, pop_like);
    let [nx, ny, _] = s.dims;
    s.data.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, plane)| {
        for (o, v) in plane.iter_mut().enumerate() {
            if progress.cancelled() {
                return;
            }
            let rho = dens.rho[k * (nx * ny) as usize + o];
            if rho <= 0.0 {
                continue;
            }
            let c = IVec3::new((o as u32 % nx) as i32, (o as u32 / nx) as i32, k as i32);
            let q = filter.to_coarse.transform_point3(dens.frame.transform_point3(c.as_vec3()));
            let (mut num, mut den, mut guide, mut wsum) = (Vec3::ZERO, 0.0f32, 0.0f32, 0.0f32);
            filter.visit(q, rho, |ci, _, w| {
                num += w * j_near.data[ci];
                den += w * d_coarse[ci];
                if merged.density[ci] > 0.0 {
                    guide += w * merged.density[ci];
                    wsum += w;
                }
            });
            if den > 0.0 && num != Vec3::ZERO {
                // The gather's ball at the coarse neighbours: their (weighted) density's.
                let guide = guide / wsum;
                let correction = dens.correction_at_lattice(c, ball(guide), sigma_t(rho), |r| whole(guide, r));
                *v = (*v + medium.sigma_s(rho) * num * (correction / den)).max(Vec3::ZERO);
            }
        }
    });
    if progress.cancelled() {
        return Err(Error::Cancelled);
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without attenuation the two ball kernels integrate alike (both as 1/d^2), so their
    /// difference integrates to zero: |integral| within 2e-4 of the kernels' mass within 4b
    /// (4 pi 4b; measured at most 3.8e-5: the midpoint sums' error at the kernels' kinks). With attenuation the wider ball loses light: positive,
    /// and more for a wider ball.
    #[test]
    fn kernel_difference_is_zero_without_attenuation_and_grows_with_the_ball() {
        let scale = 4.0 * std::f32::consts::PI * 4.0;
        for (a, b) in [(0.1f32, 0.3f32), (0.5, 1.0), (0.05, 1.0)] {
            let flat = kernel_difference(a, b, 0.0);
            eprintln!("a {a} b {b}: flat {flat:.3e} (relative {:.2e})", flat / (scale * b));
            assert!(flat.abs() < 2e-4 * scale * b, "a {a} b {b}: {flat}");
        }
        let (narrow, wide) = (kernel_difference(0.1, 0.3, 1.0), kernel_difference(0.1, 0.6, 1.0));
        eprintln!("sigma_t 1: b 0.3 {narrow:.4}, b 0.6 {wide:.4}");
        assert!(narrow > 0.0 && wide > 1.5 * narrow, "{narrow} {wide}");
    }
}
