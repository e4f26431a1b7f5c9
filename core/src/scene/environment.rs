//! Environment (dome) lighting: a uniform colour or a lat-long map with importance sampling.
//!
//! Lat-long convention (Blender's equirectangular, Z up): for a direction d *towards the sky*,
//! u = 0.5 - atan2(d.y, d.x) / (2 pi), v = 0.5 + asin(d.z) / pi, with v = 1 at the top row.

use glam::Vec3;
use std::f32::consts::PI;

use crate::sampling::{uniform_sphere, Distribution2D};

#[derive(Clone, Debug)]
pub struct LatLongMap {
    pub width: usize,
    pub height: usize,
    /// Rows top (v = 1) to bottom, RGB radiance.
    pub pixels: Vec<Vec3>,
    dist: Distribution2D,
    /// What reading the file changed, for the host to tell the user (`Scene::notes`).
    pub notes: Vec<String>,
}

impl LatLongMap {
    pub fn new(width: usize, height: usize, pixels: Vec<Vec3>) -> Self {
        // Sampling density: luminance times sin(theta) (pixel solid angle), rows in v order
        // bottom to top so that Distribution2D's v matches ours.
        let mut func = vec![0.0f32; width * height];
        for row in 0..height {
            let v = 1.0 - (row as f32 + 0.5) / height as f32;
            let sin_theta = (PI * v).sin();
            let dist_row = height - 1 - row;
            for x in 0..width {
                let c = pixels[row * width + x];
                let lum = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
                func[dist_row * width + x] = lum.max(0.0) * sin_theta + 1e-6 * sin_theta;
            }
        }
        let dist = Distribution2D::new(&func, width, height);
        LatLongMap { width, height, pixels, dist, notes: Vec::new() }
    }

    pub fn direction_to_uv(d: Vec3) -> [f32; 2] {
        let u = 0.5 - d.y.atan2(d.x) / (2.0 * PI);
        let v = 0.5 + d.z.clamp(-1.0, 1.0).asin() / PI;
        [u.rem_euclid(1.0), v.clamp(0.0, 1.0)]
    }

    pub fn uv_to_direction(uv: [f32; 2]) -> Vec3 {
        let phi = (0.5 - uv[0]) * 2.0 * PI;
        let lat = (uv[1] - 0.5) * PI;
        Vec3::new(lat.cos() * phi.cos(), lat.cos() * phi.sin(), lat.sin())
    }

    pub fn lookup(&self, d: Vec3) -> Vec3 {
        let [u, v] = Self::direction_to_uv(d);
        let x = ((u * self.width as f32) as usize).min(self.width - 1);
        let row = (((1.0 - v) * self.height as f32) as usize).min(self.height - 1);
        self.pixels[row * self.width + x]
    }

    /// Solid-angle density of `sample` for direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let uv = Self::direction_to_uv(d);
        let sin_theta = (PI * uv[1]).sin();
        if sin_theta <= 1e-6 {
            return 0.0;
        }
        self.dist.pdf(uv) / (2.0 * PI * PI * sin_theta)
    }

    /// Importance-samples a direction towards the sky; returns (direction, solid-angle pdf).
    pub fn sample(&self, u: [f32; 2]) -> (Vec3, f32) {
        let (uv, pdf_uv) = self.dist.sample(u);
        let sin_theta = (PI * uv[1]).sin();
        let d = Self::uv_to_direction(uv);
        if sin_theta <= 1e-6 {
            return (d, 0.0);
        }
        (d, pdf_uv / (2.0 * PI * PI * sin_theta))
    }
}

#[derive(Clone, Debug)]
pub struct Environment {
    /// Uniform radiance, or the map's multiplier.
    pub color: Vec3,
    pub map: Option<LatLongMap>,
}

impl Environment {
    /// Radiance arriving from direction `d` (pointing towards the sky).
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        match &self.map {
            Some(m) => m.lookup(d) * self.color,
            None => self.color,
        }
    }
    pub fn sample(&self, u: [f32; 2]) -> (Vec3, f32) {
        match &self.map {
            Some(m) => m.sample(u),
            None => (uniform_sphere(u), 1.0 / (4.0 * PI)),
        }
    }
    pub fn pdf(&self, d: Vec3) -> f32 {
        match &self.map {
            Some(m) => m.pdf(d),
            None => 1.0 / (4.0 * PI),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uv_direction_roundtrip_and_pdf_integrates_to_one() {
        for d in [Vec3::new(0.3, -0.2, 0.9).normalize(), Vec3::new(-0.7, 0.1, -0.3).normalize()] {
            let back = LatLongMap::uv_to_direction(LatLongMap::direction_to_uv(d));
            assert!((back - d).length() < 1e-4);
        }
        let (w, h) = (32, 16);
        let pixels: Vec<Vec3> = (0..w * h).map(|i| Vec3::splat(if i % 7 == 0 { 20.0 } else { 0.5 })).collect();
        let map = LatLongMap::new(w, h, pixels);
        // E[f/pdf] for f = 1 is 4 pi; E[L/pdf] is the integral of L.
        let mut rng = crate::rng::Rng::new(5, 5);
        let n = 400_000;
        let (mut ones, mut radiance) = (0.0f64, 0.0f64);
        // A direction sampled on a bin edge can round into the neighbouring bin on the way
        // back through uv: allow a few such mismatches, not systematic ones.
        let mut mismatches = 0;
        for _ in 0..n {
            let (d, pdf) = map.sample(rng.pair());
            if pdf > 0.0 {
                ones += 1.0 / pdf as f64;
                radiance += map.lookup(d).x as f64 / pdf as f64;
                if (map.pdf(d) - pdf).abs() > 1e-3 * pdf.max(1.0) {
                    mismatches += 1;
                }
            }
        }
        assert!(mismatches < n / 1000, "{mismatches} pdf mismatches");
        let mut exact = 0.0f64;
        for row in 0..h {
            let v0 = 1.0 - row as f64 / h as f64;
            let v1 = 1.0 - (row + 1) as f64 / h as f64;
            let band = 2.0 * std::f64::consts::PI * ((std::f64::consts::PI * (v0 - 0.5)).sin() - (std::f64::consts::PI * (v1 - 0.5)).sin());
            for x in 0..w {
                exact += map.pixels[row * w + x].x as f64 * band / w as f64;
            }
        }
        // f = 1 is not proportional to the pdf: MC error ~1% at this n.
        assert!((ones / n as f64 / (4.0 * std::f64::consts::PI) - 1.0).abs() < 0.03, "{}", ones / n as f64);
        assert!((radiance / n as f64 / exact - 1.0).abs() < 0.01, "{} vs {exact}", radiance / n as f64);
    }
}
