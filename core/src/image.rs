//! A rendered image: RGBA plus named RGB AOV layers, in linear radiance.

use glam::{Vec3, Vec4};

#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// Row-major, top row first. RGB radiance (W/m^2/sr), alpha = 1 - transmittance.
    pub rgba: Vec<Vec4>,
    /// Named RGB layers (e.g. `single`, `multiple`, `background`) of the same size.
    pub aovs: Vec<(String, Vec<Vec3>)>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct ImageStats {
    pub mean_rgb: [f64; 3],
    pub mean_alpha: f64,
    pub max_luminance: f64,
    pub non_finite_pixels: u64,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Image { width, height, rgba: vec![Vec4::ZERO; width as usize * height as usize], aovs: Vec::new() }
    }

    /// Refuses a `width` x `height` image (camera.width/height) over the memory budget before
    /// any of it is made: an image with its three AOVs and the per-pixel values it is
    /// assembled from is ~96 B a pixel (RGBA 16, AOVs 36, pixels 40), which is what the
    /// compositors and the reference's render allocate at their peak.
    pub fn check_budget(width: u32, height: u32, what: &str) -> crate::Result<()> {
        let pixels = width as u64 * height as u64;
        crate::budget::check(&format!("{what} of {width}x{height} pixels (camera.width/height)"), pixels.saturating_mul(96))
    }

    pub fn aov(&self, name: &str) -> Option<&[Vec3]> {
        self.aovs.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }

    pub fn stats(&self) -> ImageStats {
        let mut sum = [0f64; 4];
        let mut max_lum = 0f64;
        let mut bad = 0u64;
        for p in &self.rgba {
            if !p.is_finite() {
                bad += 1;
                continue;
            }
            for c in 0..4 {
                sum[c] += p[c] as f64;
            }
            max_lum = max_lum.max((0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z) as f64);
        }
        let n = self.rgba.len().max(1) as f64;
        ImageStats {
            mean_rgb: [sum[0] / n, sum[1] / n, sum[2] / n],
            mean_alpha: sum[3] / n,
            max_luminance: max_lum,
            non_finite_pixels: bad,
        }
    }
}

/// Relative RMSE of `a` against reference `b` over RGB: ||a - b|| / ||b||.
pub fn relative_rmse(a: &[Vec3], b: &[Vec3]) -> f64 {
    assert_eq!(a.len(), b.len());
    let (mut num, mut den) = (0f64, 0f64);
    for (x, y) in a.iter().zip(b) {
        num += (*x - *y).length_squared() as f64;
        den += y.length_squared() as f64;
    }
    if den == 0.0 {
        if num == 0.0 { 0.0 } else { f64::INFINITY }
    } else {
        (num / den).sqrt()
    }
}
