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

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, 0.4, -0.866).normalize(), Vec3::X] {
            let (t, b) = orthonormal_basis(n);
            assert!(t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5 && t.dot(b).abs() < 1e-5);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
        }
    }
}
