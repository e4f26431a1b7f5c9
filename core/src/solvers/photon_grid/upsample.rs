//! The paper's physically based upsampling of the cache (Sec. 4.3): at an output point p, the
//! cells q of the 3^3 neighbourhood Delta around p's nearest cell are blended with
//!
//!   w_L = f_exp(|p - q| | lambda, r) f_lin(|D(p) - D(q)|),
//!   J_L(p) = sum phi_q w_L / sum w_L,
//!   J_g'(p) = sum g'_q g^delta w_L / sum w_L,  delta = gamma(p) - gamma(q),
//!
//! (as read below; each neighbour's terms here also weighted by its mass, see the last items)
//!
//! with f_exp the exponential of rate lambda truncated to [0, r] and renormalised, f_lin the
//! tent max(1 - d, 0) of the density difference, and gamma the penetration depth (the mean
//! scattering order of the light, cache.rs `order`, trilinear at p as the paper says).
//!
//! The text leaves several things open; each is settled here, with the test that settles it:
//! - lambda: the paper writes tau = sigma_s (D(p) - D(q)) / 2, which is zero between cells of
//!   equal density (f_exp is then 0/0) and negative where D(q) > D(p) (weights growing with
//!   distance). The rate of exponential attenuation between p and q is the mean coefficient,
//!   sigma_s (D(p) + D(q)) / 2: that is what is used (`lambda_is_the_mean_coefficient`).
//! - f_exp as lambda r -> 0 (thin media) is 0/0 in the text's form; its limit is the tent
//!   2 (r - d) / r^2, evaluated as such below lambda r = 1e-4 (`f_exp_limits`).
//! - D's scale in f_lin: the paper's densities are simulation values in [0, 1]; here D is the
//!   density over the grid's maximum, so that scaling the density grid and dividing
//!   `density_scale` by the same factor (the same medium) gives the same S
//!   (`density_units_do_not_matter`). D(q) is the cell's mean density (its mass over its
//!   volume): what the cell's fluence phi_q = flux / mass stands for.
//! - g^delta: the formula as printed puts w_g' = g^delta in the numerator and the denominator,
//!   a weighted mean of the neighbours' g', which can never exceed the largest of them and is
//!   unchanged when all neighbours share one delta; the text's own reading ("if the upsampled
//!   point has a lower penetration depth than the extrapolated point, its anisotropy will be
//!   higher") and the HG self-convolution it appeals to (light scattered delta more times has
//!   anisotropy g' g^delta) make it an extrapolation of each neighbour's g' to p, averaged with
//!   w_L. Where g' = g^gamma exactly, the extrapolation gives it back exactly at every p and the
//!   weighted mean does not (`g_delta_extrapolates_the_self_convolution`).
//! - r: "the shortest distance from the centre of Delta to its boundary", 1.5 cell edges (the
//!   shortest edge): a cell leaving Delta as p crosses into the next cell is then at distance
//!   r or more from p, where f_exp is zero, so J is continuous (`continuous_across_cells`).
//! - Several lights: g' and the direction are the neighbours' mean-cosine vectors (cache.rs
//!   moment / weight) extrapolated and averaged as vectors, so g' = |J| and the direction is
//!   J's; with one sun it is the paper's scalar rule.
//! - Empty cells (no mass or no deposits) have no fluence to give and are skipped; where no
//!   neighbour has weight, the trilinear lobe is kept.
//! - Departure, by measurement: each neighbour's phi_q and g'_q count with w_L times its mass
//!   (ratios of w_L-weighted sums, as the trilinear lobe does with its weights). With w_L alone
//!   a rim cell holding a sliver of the medium and a few deposits weighs as much as a full one,
//!   and the dense cloud came out far worse than trilinear (docs/solvers/photon-grid.md).
//! - Each neighbour's extrapolated g'_q g^delta is capped at 0.999 (delta < 0 can exceed 1).
//! - g <= 0: g^delta is |g|^delta (floored at 1e-3 so that delta < 0 stays finite), and g' is
//!   clamped to [0, 0.999] as everywhere.

use glam::{IVec3, Vec3};

use super::cache::Tallies;
use super::reconstruct::Lobe;
use crate::medium::Medium;

/// f_exp(d | lambda, r) (Sec. 4.3): the exponential distribution of rate `lambda` truncated to
/// [0, r], shifted to reach zero at r and renormalised to a unit integral over [0, r].
pub fn f_exp(d: f32, lambda: f32, r: f32) -> f32 {
    // Also NaN d or r: no weight.
    if d.is_nan() || d >= r || r.is_nan() || r <= 0.0 {
        return 0.0;
    }
    let (d, lambda, r) = (d.max(0.0) as f64, lambda.max(0.0) as f64, r as f64);
    let a = lambda * r;
    if a < 1e-4 {
        // The limit lambda -> 0 of the form below: the tent of unit integral.
        return (2.0 * (r - d) / (r * r)) as f32;
    }
    // (f'(d) - f'(r)) / (1 - r f'(r)) with f'(d) = lambda e^(-lambda d) / (1 - e^(-a)),
    // multiplied through by (1 - e^(-a)).
    let num = lambda * ((-lambda * d).exp() - (-a).exp());
    let den = 1.0 - (-a).exp() * (1.0 + a);
    (num / den).max(0.0) as f32
}

/// f_lin(d) = max(1 - d, 0) (Sec. 4.3), d the difference of the normalised densities.
pub fn f_lin(d: f32) -> f32 {
    (1.0 - d).max(0.0)
}

/// g^delta: the factor by which `delta` more scatterings in a medium of HG anisotropy `g`
/// shrink the light's anisotropy (module doc for g <= 0).
pub fn g_delta(g: f32, delta: f32) -> f32 {
    g.abs().max(1e-3).powf(delta)
}

/// The neighbourhood data of one lobe's tallies, measured once per solve.
pub struct Upsampler<'a> {
    tallies: &'a Tallies,
    // Public for the GPU's port of `lobe` (volscatter-gpu photon_grid/reconstruct.rs), which
    // uploads these rather than measuring them again.
    /// Each cell's mean density (mass / volume), over the grid's maximum.
    pub cell_density: Vec<f32>,
    /// 1 / the grid's maximum density.
    pub density_norm: f32,
    /// sigma_s per unit density (the channels' mean).
    pub sigma_s: f32,
    /// The medium's HG g.
    pub g: f32,
    /// r: 1.5 of the shortest cell edge (world units).
    pub r: f32,
}

impl<'a> Upsampler<'a> {
    pub fn new(medium: &Medium, tallies: &'a Tallies) -> Self {
        let m = tallies.frame.index_to_world.matrix3;
        let volume = m.determinant().abs().max(1e-30);
        let edge = m.x_axis.length().min(m.y_axis.length()).min(m.z_axis.length());
        let density_norm = 1.0 / medium.grid.max_value().max(1e-30);
        Upsampler {
            tallies,
            cell_density: tallies.mass.iter().map(|&m| m / volume * density_norm).collect(),
            density_norm,
            sigma_s: medium.sigma_s(1.0).element_sum() / 3.0,
            g: medium.g,
            r: 1.5 * edge,
        }
    }

    /// The lobe at world point `x` where the density is `rho`.
    pub fn lobe(&self, x: Vec3, rho: f32) -> Lobe {
        let t = self.tallies;
        let trilinear = t.lobe(x);
        let dims = IVec3::new(t.frame.dims[0] as i32, t.frame.dims[1] as i32, t.frame.dims[2] as i32);
        let centre = t.world_to_cell.transform_point3(x).round().as_ivec3();
        let (dp, gamma_p) = (rho * self.density_norm, trilinear.order);
        let (mut flux, mut mass, mut moment, mut weight) = (Vec3::ZERO, 0.0f32, Vec3::ZERO, 0.0f32);
        for c in 0..27 {
            let q = centre + IVec3::new(c % 3 - 1, (c / 3) % 3 - 1, c / 9 - 1);
            if q.cmplt(IVec3::ZERO).any() || q.cmpge(dims).any() {
                continue;
            }
            let i = (q.x + dims.x * (q.y + dims.y * q.z)) as usize;
            if t.mass[i] <= 0.0 || t.weight[i] <= 0.0 {
                continue;
            }
            let dq = self.cell_density[i];
            let lambda = self.sigma_s * (dp + dq) * 0.5 / self.density_norm;
            let distance = (t.frame.index_to_world.transform_point3(q.as_vec3()) - x).length();
            let w = f_exp(distance, lambda, self.r) * f_lin((dp - dq).abs());
            if w <= 0.0 {
                continue;
            }
            // Each neighbour's fluence phi_q = flux / mass and mean-cosine vector
            // moment / weight, averaged with w_L times the cell's mass (its deposit weight):
            // the ratios of sums, as the trilinear lobe (module doc).
            let gamma_q = t.order[i] / t.weight[i];
            let g_q = t.moment[i].length() / t.weight[i];
            let extrapolated = g_delta(self.g, gamma_p - gamma_q).min(0.999 / g_q.max(1e-6));
            flux += t.flux[i] * w;
            mass += t.mass[i] * w;
            moment += t.moment[i] * (extrapolated * w);
            weight += t.weight[i] * w;
        }
        if mass <= 0.0 || weight <= 0.0 {
            return trilinear;
        }
        let len = moment.length();
        Lobe {
            fluence: flux / mass,
            g: (len / weight).min(0.999),
            direction: if len > 0.0 { moment / len } else { Vec3::ZERO },
            order: gamma_p,
            deposits: trilinear.deposits,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::{procedural, GridLimits};
    use crate::rng::Rng;
    use crate::stages::ScatteringGrid;

    /// The plume (16^3) with its density times `k` and `density_scale` over `k`: the same
    /// medium in other density units.
    fn plume(k: f32) -> Medium {
        let (grid, to_world) = procedural::on_cube(16, GridLimits::default(), |p| k * procedural::plume_density(p)).unwrap();
        Medium::new(grid, to_world, Vec3::splat(8.0 / k), Vec3::splat(0.99), 0.9)
    }

    /// Random tallies on a cache of 6 cells over `medium` (seeded), their integrals of the
    /// density (flux, mass, weight, moment) times `k`.
    fn tallies(medium: &Medium, k: f32) -> Tallies {
        let mut frame = ScatteringGrid::over_medium(medium, 6).unwrap();
        let n = frame.len();
        frame.data = Vec::new();
        let mut rng = Rng::new(7, 0);
        let mut t = Tallies { world_to_cell: frame.index_to_world.inverse(), frame, flux: vec![], moment: vec![], weight: vec![], order: vec![], count: vec![], mass: vec![] };
        for _ in 0..n {
            let mass = rng.f32() * k;
            let weight = mass * (0.5 + rng.f32());
            t.mass.push(mass);
            t.flux.push(Vec3::splat(weight));
            t.weight.push(weight);
            t.moment.push(Vec3::new(0.3, -0.2, 0.5 + rng.f32() * 0.3) * weight);
            t.order.push((2.0 + 6.0 * rng.f32()) * weight);
            t.count.push(1000);
        }
        t
    }

    /// f_exp has a unit integral over [0, r], is zero at and past r, and decreases with d, for
    /// thin and thick media; as lambda r -> 0 it tends to the tent 2 (r - d) / r^2 (the
    /// text's form is 0/0 there), continuously across the switch at lambda r = 1e-4.
    #[test]
    fn f_exp_limits() {
        let r = 1.5f32;
        for lambda in [0.0f32, 1e-5, 1e-3, 0.1, 1.0, 5.0, 40.0] {
            let n = 20000;
            let integral: f64 = (0..n).map(|i| f_exp((i as f32 + 0.5) * r / n as f32, lambda, r) as f64).sum::<f64>() * r as f64 / n as f64;
            assert!((integral - 1.0).abs() < 1e-3, "lambda {lambda}: integral {integral}");
            assert_eq!(f_exp(r, lambda, r), 0.0);
            assert_eq!(f_exp(2.0 * r, lambda, r), 0.0);
            for k in 0..10 {
                let d = k as f32 * 0.1 * r;
                assert!(f_exp(d, lambda, r) > f_exp(d + 0.1 * r, lambda, r), "lambda {lambda}, d {d}");
            }
        }
        // Either side of the tent switch (a = 1e-4): within 1e-4 relative.
        let (below, above) = (f_exp(0.3, 0.99e-4 / r, r), f_exp(0.3, 1.01e-4 / r, r));
        assert!((below / above - 1.0).abs() < 1e-4, "{below} vs {above}");
        assert!((f_exp(0.3, 0.0, r) - 2.0 * (r - 0.3) / (r * r)).abs() < 1e-6);
    }

    /// The rate is the mean coefficient sigma_s (D(p) + D(q)) / 2: symmetric in p and q,
    /// positive between cells of equal density (where the printed difference would be 0, and
    /// f_exp with it 0/0 in the text's form, and negative where D(q) > D(p), giving weights
    /// that grow with distance); a denser medium between them weights distant cells less.
    #[test]
    fn lambda_is_the_mean_coefficient() {
        let r = 1.5;
        let rate = |dp: f32, dq: f32| 4.0 * (dp + dq) * 0.5;
        assert_eq!(rate(0.2, 0.8), rate(0.8, 0.2));
        assert!(rate(0.5, 0.5) > 0.0);
        // Far cells lose weight against near ones faster in denser media.
        let ratio = |lambda: f32| f_exp(1.2, lambda, r) / f_exp(0.2, lambda, r);
        assert!(ratio(rate(1.0, 1.0)) < ratio(rate(0.1, 0.1)));
    }

    /// With g' = g^gamma in every cell (light scattered gamma times, HG self-convolution), the
    /// extrapolation g'_q g^(gamma_p - gamma_q) is g^gamma_p for every neighbour, so any
    /// weighted mean of it is exact; the printed weighted mean of g'_q with weights g^delta
    /// is not (it stays between the neighbours' values, and here is off by more than 10%).
    #[test]
    fn g_delta_extrapolates_the_self_convolution() {
        let g = 0.9f32;
        let gammas = [2.0f32, 3.5, 6.0];
        let weights = [0.2f32, 0.5, 0.3];
        let gamma_p = 2.5f32;
        let exact = g.powf(gamma_p);
        let (mut ours, mut printed_num, mut printed_den, mut sum) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (gq, w) in gammas.iter().zip(weights) {
            let g_q = g.powf(*gq);
            let f = g_delta(g, gamma_p - gq);
            ours += g_q * f * w;
            printed_num += g_q * f * w;
            printed_den += f * w;
            sum += w;
        }
        let (ours, printed) = (ours / sum, printed_num / printed_den);
        assert!((ours / exact - 1.0).abs() < 1e-5, "extrapolated {ours} vs g^gamma {exact}");
        assert!((printed / exact - 1.0).abs() > 0.1, "printed form {printed} vs {exact}");
        // A point less deep than its neighbour is more anisotropic (the text's remark).
        assert!(g_delta(g, -1.0) > 1.0 && g_delta(g, 1.0) < 1.0);
    }

    /// The same medium in other density units (grid x 10, density_scale / 10) gives the same
    /// lobes: D is normalised by the grid's maximum (a raw difference in f_lin would not be).
    #[test]
    fn density_units_do_not_matter() {
        let (a, b) = (plume(1.0), plume(10.0));
        let (ta, tb) = (tallies(&a, 1.0), tallies(&b, 10.0));
        let (ua, ub) = (Upsampler::new(&a, &ta), Upsampler::new(&b, &tb));
        let mut rng = Rng::new(3, 0);
        for _ in 0..200 {
            let x = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1.6 - 0.8;
            let (la, lb) = (ua.lobe(x, a.density_world(x)), ub.lobe(x, b.density_world(x)));
            assert!((la.fluence - lb.fluence).abs().max_element() <= 1e-4 * la.fluence.max_element().max(1e-6), "{la:?} vs {lb:?}");
            assert!((la.g - lb.g).abs() < 1e-4, "{la:?} vs {lb:?}");
        }
    }

    /// Crossing from one cell's domain into the next (p's nearest cell, and Delta with it,
    /// changes) J_L and g' move only as much as p does: the cells leaving Delta are at r or
    /// farther, where f_exp is 0.
    #[test]
    fn continuous_across_cells() {
        let m = plume(1.0);
        let t = tallies(&m, 1.0);
        let u = Upsampler::new(&m, &t);
        let to_world = t.frame.index_to_world;
        let mut jumps = 0;
        for c in [IVec3::new(2, 2, 2), IVec3::new(2, 3, 1), IVec3::new(3, 2, 3)] {
            for axis in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE.normalize()] {
                let q = c.as_vec3() + Vec3::splat(0.1) + axis * 0.5;
                let (x0, x1) = (to_world.transform_point3(q - axis * 1e-3), to_world.transform_point3(q + axis * 1e-3));
                let (l0, l1) = (u.lobe(x0, m.density_world(x0)), u.lobe(x1, m.density_world(x1)));
                let rel = ((l0.fluence - l1.fluence).abs().max_element()) / l0.fluence.max_element().max(1e-6);
                eprintln!("cell {c}, axis {axis}: fluence {:.5} -> {:.5} ({rel:.2e}), g' {:.4} -> {:.4}", l0.fluence.x, l1.fluence.x, l0.g, l1.g);
                // 2e-3 of a cell moves p: a smooth J changes by about that much, a jump (a
                // neighbour of weight ~1/27 entering) by ~1e-2 or more.
                if rel > 5e-3 || (l0.g - l1.g).abs() > 5e-3 {
                    jumps += 1;
                }
            }
        }
        assert_eq!(jumps, 0);
    }
}
