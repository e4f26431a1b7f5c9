//! Henyey-Greenstein phase function, pbrt-v4 conventions.
//!
//! `cos_theta` is the cosine between the *propagation* directions of the incoming and the
//! scattered light: forward scattering is `cos_theta = 1`. The function integrates to 1 over the
//! sphere (the 1/4pi factor is included).

use glam::Vec3;
use std::f32::consts::PI;

use crate::sampling::orthonormal_basis;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HenyeyGreenstein {
    pub g: f32,
}

impl HenyeyGreenstein {
    /// `g` is clamped to (-0.999, 0.999): at |g| = 1 the lobe is a delta and the density infinite.
    pub fn new(g: f32) -> Self {
        Self { g: g.clamp(-0.999, 0.999) }
    }

    /// Density per steradian for the angle between propagation directions.
    #[inline]
    pub fn eval(&self, cos_theta: f32) -> f32 {
        hg(cos_theta, self.g)
    }

    /// Samples a propagation direction after scattering, given the propagation direction
    /// `dir_in` of the incoming light. Returns the new direction; its density is
    /// `eval(dot(dir_in, result))`.
    #[inline]
    pub fn sample(&self, dir_in: Vec3, u: [f32; 2]) -> Vec3 {
        let g = self.g;
        let cos_theta = if g.abs() < 1e-3 {
            1.0 - 2.0 * u[0]
        } else {
            let s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u[0]);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = 2.0 * PI * u[1];
        let (t, b) = orthonormal_basis(dir_in);
        (t * (sin_theta * phi.cos()) + b * (sin_theta * phi.sin()) + dir_in * cos_theta).normalize()
    }
}

/// HG density with the 1/4pi factor; `cos_theta` between propagation directions.
#[inline]
pub fn hg(cos_theta: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
}

/// Fraction of HG energy scattered into the cone `cos_theta >= cos_max` around the forward
/// direction: the HG cumulative distribution in `cos_theta` (used by POP's solid-angle weights).
pub fn hg_cone_fraction(cos_max: f32, g: f32) -> f32 {
    let cos_max = cos_max.clamp(-1.0, 1.0);
    if g.abs() < 1e-4 {
        return (1.0 - cos_max) * 0.5;
    }
    // P(cos >= c) = (1-g^2)/(2g) * [ (1+g^2-2g c)^-1/2 - (1+g^2-2g)^-1/2 ]
    let a = 1.0 + g * g;
    let f = |c: f32| 1.0 / (a - 2.0 * g * c).max(1e-12).sqrt();
    ((1.0 - g * g) / (2.0 * g) * (f(1.0) - f(cos_max))).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Numerical integral of `f(cos)` over the sphere (midpoint rule in cos_theta).
    fn integrate(f: impl Fn(f32) -> f64) -> f64 {
        let n = 200_000;
        let mut s = 0.0;
        for i in 0..n {
            let c = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
            s += f(c as f32) * 2.0 / n as f64;
        }
        s * 2.0 * std::f64::consts::PI
    }

    #[test]
    fn hg_is_normalised_and_mean_cosine_is_g() {
        for g in [-0.7f32, 0.0, 0.3, 0.8, 0.95] {
            let norm = integrate(|c| hg(c, g) as f64);
            assert!((norm - 1.0).abs() < 2e-4, "g={g}: integral {norm}");
            let mean = integrate(|c| (c * hg(c, g)) as f64);
            assert!((mean - g as f64).abs() < 2e-4, "g={g}: mean cosine {mean}");
        }
    }

    #[test]
    fn cone_fraction_matches_integral() {
        for g in [-0.5f32, 0.0, 0.6, 0.9] {
            for cmax in [-0.5f32, 0.0, 0.5, 0.9] {
                let direct = integrate(|c| if c >= cmax { hg(c, g) as f64 } else { 0.0 });
                let cdf = hg_cone_fraction(cmax, g) as f64;
                assert!((direct - cdf).abs() < 1e-3, "g={g} c={cmax}: {direct} vs {cdf}");
            }
        }
    }

    /// Chi-square test of the sampled cos_theta against the analytic HG distribution, 40 bins
    /// equally probable under HG. With 40 bins (39 dof) the 99.9% quantile is 72.1; a sampler
    /// with the wrong sign of g or a wrong inversion gives values in the thousands.
    #[test]
    fn sampling_matches_density_chi_square() {
        let mut rng = Rng::new(7, 0);
        for g in [-0.6f32, 0.0, 0.5, 0.9] {
            let hgp = HenyeyGreenstein::new(g);
            let bins = 40;
            // Bin edges: invert the analytic CDF numerically (bisection).
            let cdf = |c: f32| 1.0 - hg_cone_fraction(c, g);
            let mut edges = vec![-1.0f32];
            for k in 1..bins {
                let target = k as f32 / bins as f32;
                let (mut lo, mut hi) = (-1.0f32, 1.0f32);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if cdf(mid) < target { lo = mid } else { hi = mid }
                }
                edges.push(0.5 * (lo + hi));
            }
            edges.push(1.0);
            let n = 200_000;
            let mut counts = vec![0u32; bins];
            let dir_in = Vec3::new(0.3, -0.5, 0.8).normalize();
            for _ in 0..n {
                let d = hgp.sample(dir_in, [rng.f32(), rng.f32()]);
                assert!((d.length() - 1.0).abs() < 1e-4);
                let c = d.dot(dir_in);
                let k = edges.partition_point(|&e| e <= c).saturating_sub(1).min(bins - 1);
                counts[k] += 1;
            }
            let expected = n as f64 / bins as f64;
            let chi2: f64 = counts.iter().map(|&o| (o as f64 - expected).powi(2) / expected).sum();
            assert!(chi2 < 72.1, "g={g}: chi-square {chi2} over 39 dof");
        }
    }
}
