//! Sampling helpers shared by the solvers: frames, spheres, cones, piecewise-constant
//! distributions (for environment-map importance sampling).

use glam::Vec3;
use std::f32::consts::PI;

/// Two unit vectors completing `n` (unit) to an orthonormal basis (Duff et al. 2017).
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

#[inline]
pub fn uniform_sphere(u: [f32; 2]) -> Vec3 {
    let z = 1.0 - 2.0 * u[0];
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform direction in the cone around unit `axis` whose half-angle has
/// `1 - cos = one_minus_cos_max` (passed as such for precision at tiny angles);
/// density 1 / (2 pi one_minus_cos_max).
#[inline]
pub fn uniform_cone(axis: Vec3, one_minus_cos_max: f32, u: [f32; 2]) -> Vec3 {
    let cos_t = 1.0 - u[0] * one_minus_cos_max;
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    let (t, b) = orthonormal_basis(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

/// Piecewise-constant 1D distribution on [0, 1).
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    integral: f32,
}

impl Distribution1D {
    pub fn new(func: &[f32]) -> Self {
        let n = func.len().max(1);
        let mut func: Vec<f32> = func.iter().map(|&f| if f.is_finite() { f.max(0.0) } else { 0.0 }).collect();
        if func.is_empty() {
            func.push(0.0);
        }
        let mut cdf = vec![0.0f32; n + 1];
        let mut acc = 0.0f64;
        for i in 0..n {
            acc += func[i] as f64 / n as f64;
            cdf[i + 1] = acc as f32;
        }
        let integral = acc as f32;
        if integral <= 0.0 {
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f32 / n as f32;
            }
        } else {
            for c in cdf.iter_mut() {
                *c /= integral;
            }
        }
        Self { func, cdf, integral }
    }
    pub fn len(&self) -> usize {
        self.func.len()
    }
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }
    pub fn integral(&self) -> f32 {
        self.integral
    }
    /// Returns (x in [0,1), pdf(x), bin index).
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        let i = (self.cdf.partition_point(|&c| c <= u).saturating_sub(1)).min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 { (u - self.cdf[i]) / width } else { 0.5 };
        let pdf = self.pdf_bin(i);
        (((i as f32 + du.clamp(0.0, 0.99999)) / n as f32).min(0.999_999), pdf, i)
    }
    pub fn pdf_bin(&self, i: usize) -> f32 {
        if self.integral > 0.0 { self.func[i] / self.integral } else { 1.0 }
    }
}

/// Piecewise-constant 2D distribution on [0,1)^2, rows indexed by v.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `func` is `height` rows of `width` values.
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        let rows: Vec<Distribution1D> =
            (0..height).map(|v| Distribution1D::new(&func[v * width..(v + 1) * width])).collect();
        let marginal = Distribution1D::new(&rows.iter().map(|r| r.integral()).collect::<Vec<_>>());
        Self { rows, marginal }
    }
    /// Returns ((u, v), pdf over [0,1)^2).
    pub fn sample(&self, u: [f32; 2]) -> ([f32; 2], f32) {
        let (v, pdf_v, iv) = self.marginal.sample(u[1]);
        let (uu, pdf_u, _) = self.rows[iv].sample(u[0]);
        ([uu, v], pdf_u * pdf_v)
    }
    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        let h = self.rows.len();
        let iv = ((uv[1] * h as f32) as usize).min(h - 1);
        let row = &self.rows[iv];
        let w = row.len();
        let iu = ((uv[0] * w as f32) as usize).min(w - 1);
        if self.marginal.integral() <= 0.0 {
            return 1.0;
        }
        row.pdf_bin(iu) * self.marginal.pdf_bin(iv)
    }
}

/// Cosine-weighted direction about unit `normal` (Malley's method through the concentric
/// disc): density cos(theta) / pi over the hemisphere `normal` points to.
#[inline]
pub fn cosine_hemisphere(normal: Vec3, u: [f32; 2]) -> Vec3 {
    let (x, y) = concentric_disk(u);
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    let (t, b) = orthonormal_basis(normal);
    (t * x + b * y + normal * z).normalize()
}

/// A discrete distribution over indices with probabilities proportional to non-negative
/// weights. The cumulative sum is kept in f64: with millions of entries (an emissive grid's
/// cells) an f32 sum loses the small ones, and then a sample's probability no longer matches
/// the weight it is divided by.
#[derive(Clone, Debug, Default)]
pub struct DiscreteDistribution {
    /// cdf[i] = sum of the weights before i; the last entry is the total.
    cdf: Vec<f64>,
}

impl DiscreteDistribution {
    /// Non-finite and negative weights count as zero.
    pub fn new(weights: impl IntoIterator<Item = f64>) -> Self {
        let mut cdf = vec![0.0f64];
        for w in weights {
            let w = if w.is_finite() { w.max(0.0) } else { 0.0 };
            cdf.push(cdf.last().unwrap() + w);
        }
        DiscreteDistribution { cdf }
    }
    pub fn len(&self) -> usize {
        self.cdf.len() - 1
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn total(&self) -> f64 {
        *self.cdf.last().unwrap_or(&0.0)
    }
    /// Probability of index `i`.
    pub fn probability(&self, i: usize) -> f64 {
        (self.cdf[i + 1] - self.cdf[i]) / self.total()
    }
    /// For `u` in [0, 1): (index, its probability, `u` rescaled to [0, 1) within the index's
    /// share, for reuse as a fresh uniform). Never returns an index of zero weight; None when
    /// every weight is zero.
    pub fn sample(&self, u: f32) -> Option<(usize, f64, f32)> {
        let total = self.total();
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        let target = u.clamp(0.0, 1.0) as f64 * total;
        // The first index whose cumulative end exceeds the target (zero-weight entries have
        // equal ends and are skipped).
        let i = (self.cdf[1..].partition_point(|&c| c <= target)).min(self.len() - 1);
        // Rounding at the top end could land on trailing zero weights: step back to a live one.
        let i = (0..=i).rev().find(|&k| self.cdf[k + 1] > self.cdf[k])?;
        let (lo, hi) = (self.cdf[i], self.cdf[i + 1]);
        let rest = (((target - lo) / (hi - lo)) as f32).clamp(0.0, 0.999_999_94);
        Some((i, (hi - lo) / total, rest))
    }
}

/// Pearson's chi-square statistic of observed `counts` against expected probabilities
/// `probs` (summing to 1): sum (o - n p)^2 / (n p) over the bins with p > 0. Tests compare it
/// with `chi_square_quantile`; bins should expect at least ~5 samples each.
pub fn chi_square(counts: &[u64], probs: &[f64]) -> f64 {
    let n: u64 = counts.iter().sum();
    counts
        .iter()
        .zip(probs)
        .filter(|(_, &p)| p > 0.0)
        .map(|(&o, &p)| {
            let e = n as f64 * p;
            (o as f64 - e).powi(2) / e
        })
        .sum()
}

/// `chi_square` after pooling the bins that expect fewer than `min_expected` samples into one
/// (the statistic is only chi-square distributed when every bin expects a few): returns the
/// statistic and its degrees of freedom (bins after pooling, minus one).
pub fn chi_square_pooled(counts: &[u64], probs: &[f64], min_expected: f64) -> (f64, usize) {
    let n: u64 = counts.iter().sum();
    let (mut c, mut p, mut rest_c, mut rest_p) = (Vec::new(), Vec::new(), 0u64, 0.0f64);
    for (&o, &q) in counts.iter().zip(probs) {
        if q * n as f64 >= min_expected {
            c.push(o);
            p.push(q);
        } else {
            rest_c += o;
            rest_p += q;
        }
    }
    if rest_p > 0.0 || rest_c > 0 {
        c.push(rest_c);
        p.push(rest_p);
    }
    (chi_square(&c, &p), c.len().saturating_sub(1))
}

/// The 99.9% quantile of the chi-square distribution with `dof` degrees of freedom, by the
/// Wilson-Hilferty approximation (within 1% of the tables for dof >= 10): a correct sampler
/// fails a test at this bound once in a thousand seeds.
pub fn chi_square_quantile_999(dof: usize) -> f64 {
    let k = dof.max(1) as f64;
    let z = 3.090_232; // standard normal 99.9% quantile
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + z * a.sqrt()).powi(3)
}

/// Shirley-Chiu concentric map from the unit square to the unit disc.
pub fn concentric_disk(u: [f32; 2]) -> (f32, f32) {
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let q = std::f32::consts::FRAC_PI_4;
    let (r, phi) = if a.abs() > b.abs() { (a, q * (b / a)) } else { (b, 2.0 * q - q * (a / b)) };
    (r * phi.cos(), r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distribution_2d_pdf_matches_sampling() {
        let (w, h) = (8, 4);
        let func: Vec<f32> = (0..w * h).map(|i| ((i * 7) % 5) as f32 + 0.1).collect();
        let d = Distribution2D::new(&func, w, h);
        let mut rng = crate::rng::Rng::new(3, 1);
        let n = 200_000;
        let mut counts = vec![0f64; w * h];
        for _ in 0..n {
            let (uv, pdf) = d.sample(rng.pair());
            assert!((pdf - d.pdf(uv)).abs() < 1e-4 * pdf.max(1.0));
            let i = (uv[1] * h as f32) as usize * w + (uv[0] * w as f32) as usize;
            counts[i] += 1.0;
        }
        let total: f32 = func.iter().sum();
        for i in 0..w * h {
            let expected = func[i] / total;
            assert!((counts[i] / n as f64 - expected as f64).abs() < 0.005, "bin {i}");
        }
    }

    /// Table values of the chi-square 99.9% quantile: 29.59 (10 dof), 72.05 (39), 148.23 (99).
    #[test]
    fn chi_square_quantile_matches_tables() {
        for (dof, table) in [(10, 29.59), (39, 72.05), (99, 148.23)] {
            let q = chi_square_quantile_999(dof);
            assert!((q / table - 1.0).abs() < 0.01, "{dof}: {q} vs {table}");
        }
    }

    /// Pooling: bins expecting fewer than 5 samples become one bin (here the last two, which
    /// expect 2 each of 103), and the statistic is Pearson's over what is left (by hand: 3
    /// bins, 2 dof).
    #[test]
    fn chi_square_pools_small_bins() {
        let (chi2, dof) = chi_square_pooled(&[50, 50, 1, 2], &[0.48, 0.48, 0.02, 0.02], 5.0);
        let e: [f64; 3] = [103.0 * 0.48, 103.0 * 0.48, 103.0 * 0.04];
        let by_hand = (50.0 - e[0]).powi(2) / e[0] * 2.0 + (3.0 - e[2]).powi(2) / e[2];
        assert_eq!(dof, 2);
        assert!((chi2 - by_hand).abs() < 1e-9, "{chi2} vs {by_hand}");
    }

    /// Frequencies follow the weights (chi-square at 99.9%), zero weights are never drawn, the
    /// returned probability is weight / total and the rescaled uniform is uniform (its mean 0.5
    /// within 5 standard errors, 1/sqrt(12 n)).
    #[test]
    fn discrete_distribution_follows_its_weights() {
        let weights = [0.0, 3.0, 0.0, 1.0, 0.5, 0.0, 2.5, 0.0];
        let d = DiscreteDistribution::new(weights.iter().copied());
        assert_eq!(d.len(), 8);
        assert!(DiscreteDistribution::new([0.0, 0.0]).sample(0.3).is_none());
        let probs: Vec<f64> = weights.iter().map(|w| w / 7.0).collect();
        let mut rng = crate::rng::Rng::new(11, 0);
        let n = 100_000;
        let mut counts = vec![0u64; 8];
        let mut rest_sum = 0.0f64;
        for _ in 0..n {
            let (i, p, rest) = d.sample(rng.f32()).unwrap();
            assert!(weights[i] > 0.0 && (p - probs[i]).abs() < 1e-12 && (0.0..1.0).contains(&rest));
            counts[i] += 1;
            rest_sum += rest as f64;
        }
        assert_eq!(d.sample(0.999_999_94).unwrap().0, 6);
        let chi2 = chi_square(&counts, &probs);
        assert!(chi2 < chi_square_quantile_999(3), "chi-square {chi2}");
        assert!((rest_sum / n as f64 - 0.5).abs() < 5.0 / (12.0 * n as f64).sqrt());
    }

    /// Cosine-weighted directions: unit, in the normal's hemisphere, and E[cos] = 2/3 (within 5
    /// standard errors; the variance of cos under this density is 1/2 - 4/9 = 1/18).
    #[test]
    fn cosine_hemisphere_has_the_cosine_law() {
        let n = Vec3::new(0.2, -0.6, 0.5).normalize();
        let mut rng = crate::rng::Rng::new(12, 0);
        let k = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..k {
            let w = cosine_hemisphere(n, rng.pair());
            assert!((w.length() - 1.0).abs() < 1e-5 && w.dot(n) >= -1e-6);
            sum += w.dot(n) as f64;
        }
        let se = (1.0f64 / 18.0 / k as f64).sqrt();
        assert!((sum / k as f64 - 2.0 / 3.0).abs() < 5.0 * se, "{}", sum / k as f64);
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, 0.4, -0.866).normalize(), Vec3::X] {
            let (t, b) = orthonormal_basis(n);
            assert!(t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && t.dot(b).abs() < 1e-5);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
        }
    }
}
