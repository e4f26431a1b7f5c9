//! Blackbody emission as Cycles' Principled Volume defines it (Blender 5.0; the same formula in
//! EEVEE's `node_volume_principled` and Cycles' SVM principled-volume node):
//!
//! ```text
//! T         = max(temperature * max(attribute, 0), 0)                    (kelvin)
//! intensity = sigma_SB * 1e-6 / pi * mix(1, T^4, blackbody_intensity)    (if blackbody_intensity > 1e-3)
//! emission  = blackbody_tint * intensity * colour(T)                     (if intensity > 1e-5)
//! ```
//!
//! with sigma_SB = 5.670373e-8 W m^-2 K^-4 (Stefan-Boltzmann: sigma T^4 / pi is the radiance of a
//! black surface; Cycles scales it by 1e-6 so that flames of ~1500 K need strengths near 1) and
//! colour(T) the chromaticity of Planck's spectrum in linear Rec.709 normalised to luminance
//! Y = 1, held constant below 800 K and above 12000 K (Cycles' range).
//!
//! Cycles evaluates colour(T) with a fitted rational approximation. Here it is computed from its
//! definition: Planck's law summed against the CIE 1931 2-degree colour matching functions
//! (cie1931.rs, 5 nm), XYZ to linear Rec.709 (D65), divided by Y. Negative components
//! (temperatures below ~1900 K, whose colour is outside the Rec.709 gamut) are clamped to zero:
//! emission cannot be negative (Cycles' Principled Volume keeps them, its Blackbody node clamps
//! them too). Tabulated once every 10 K.

use glam::Vec3;
use std::sync::OnceLock;

use super::cie1931;

/// Stefan-Boltzmann constant (W m^-2 K^-4), as Cycles uses it.
pub const STEFAN_BOLTZMANN: f32 = 5.670373e-8;
/// Cycles' scale of blackbody radiance (see the module comment).
const CYCLES_SCALE: f32 = 1e-6;
const T_MIN: f32 = 800.0;
const T_MAX: f32 = 12000.0;
const T_STEP: f32 = 10.0;

/// The scalar part of Principled Volume's blackbody emission for temperature `t` (K).
pub fn principled_intensity(t: f32, blackbody_intensity: f32) -> f32 {
    if blackbody_intensity <= 1e-3 {
        return 0.0;
    }
    let t4 = (t * t) * (t * t);
    let intensity = STEFAN_BOLTZMANN * CYCLES_SCALE / std::f32::consts::PI * ((1.0 - blackbody_intensity) + blackbody_intensity * t4);
    if intensity > 1e-5 { intensity } else { 0.0 }
}

/// Linear Rec.709 colour of a blackbody at `t` kelvin, luminance 1 (components >= 0).
pub fn colour(t: f32) -> Vec3 {
    let table = TABLE.get_or_init(build_table);
    let x = ((t.clamp(T_MIN, T_MAX) - T_MIN) / T_STEP).max(0.0);
    let i = (x as usize).min(table.len() - 2);
    let f = x - i as f32;
    table[i] * (1.0 - f) + table[i + 1] * f
}

static TABLE: OnceLock<Vec<Vec3>> = OnceLock::new();

fn build_table() -> Vec<Vec3> {
    let n = ((T_MAX - T_MIN) / T_STEP).round() as usize + 1;
    (0..n).map(|i| colour_exact(T_MIN as f64 + i as f64 * T_STEP as f64)).collect()
}

/// Planck's spectral radiance up to a constant factor (only the chromaticity is used):
/// lambda^-5 / (exp(c2 / (lambda T)) - 1), c2 = hc/k = 1.4387769e7 nm K.
fn planck_shape(l_nm: f64, t: f64) -> f64 {
    let l = l_nm * 1e-3; // micrometres keep the numbers moderate
    l.powi(-5) / ((1.4387769e7 / (l_nm * t)).exp_m1())
}

fn colour_exact(t: f64) -> Vec3 {
    let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
    // The CIE table's 5 nm sums (the CIE's own practice for tristimulus values).
    for (i, [cx, cy, cz]) in cie1931::XYZ.iter().enumerate() {
        let b = planck_shape(cie1931::START_NM + cie1931::STEP_NM * i as f64, t);
        x += b * cx;
        y += b * cy;
        z += b * cz;
    }
    let (x, z) = (x / y, z / y);
    // XYZ -> linear Rec.709 / sRGB primaries, D65 white (IEC 61966-2-1).
    let r = 3.2404542 * x - 1.5371385 - 0.4985314 * z;
    let g = -0.9692660 * x + 1.8760108 + 0.0415560 * z;
    let b = 0.0556434 * x - 0.2040259 + 1.0572252 * z;
    Vec3::new(r as f32, g as f32, b as f32).max(Vec3::ZERO)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luminance(c: Vec3) -> f32 {
        c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
    }

    /// The colour has luminance 1 where it is inside the gamut, is reddish when cool and bluish
    /// when hot, and is near white at D65's correlated colour temperature (6504 K).
    #[test]
    fn blackbody_colour_is_normalised_and_ordered() {
        for t in [2000.0, 4000.0, 6504.0, 9000.0, 12000.0] {
            assert!((luminance(colour(t)) - 1.0).abs() < 2e-3, "{t}: {}", colour(t));
        }
        let (warm, white, hot) = (colour(1500.0), colour(6504.0), colour(12000.0));
        assert!(warm.x > warm.y && warm.y > warm.z, "{warm}");
        assert!(hot.z > hot.y && hot.y > hot.x, "{hot}");
        assert!((white - Vec3::ONE).abs().max_element() < 0.05, "{white}");
        // Constant outside Cycles' range.
        assert_eq!(colour(100.0), colour(800.0));
        assert_eq!(colour(1e5), colour(12000.0));
    }

    /// Against Cycles itself: a Blackbody node into an Emission shader of strength 1 on a plane
    /// filling the view, rendered by Cycles (bpy 5.0.1, 1 sample, 4x4 pixels, linear EXR); the
    /// node clamps negative components, as `colour` does. Tolerance 0.005 + 0.5%.
    #[test]
    fn blackbody_colour_matches_cycles() {
        let cycles = [
            (1000.0, [4.60136, 0.03904, 0.0]),
            (1500.0, [3.26431, 0.43405, 0.0]),
            (2000.0, [2.5201, 0.64685, 0.02041]),
            (3000.0, [1.77084, 0.84428, 0.27222]),
            (4000.0, [1.41412, 0.92364, 0.53367]),
            (6500.0, [1.04255, 0.98405, 1.03527]),
            (12000.0, [0.8263, 0.99451, 1.56631]),
        ];
        for (t, c) in cycles {
            let (ours, theirs) = (colour(t), Vec3::from(c));
            assert!(((ours - theirs).abs() - (Vec3::splat(0.005) + 0.005 * theirs)).max_element() < 0.0, "{t} K: {ours} vs Cycles {theirs}");
        }
    }

    #[test]
    fn principled_intensity_follows_stefan_boltzmann() {
        let t = 1500.0f32;
        let expected = 5.670373e-8 * 1e-6 / std::f32::consts::PI * t.powi(4);
        assert!((principled_intensity(t, 1.0) - expected).abs() < 1e-6 * expected);
        assert_eq!(principled_intensity(t, 0.0), 0.0);
        // Below ~153 K the intensity is under Cycles' 1e-5 cut.
        assert_eq!(principled_intensity(150.0, 1.0), 0.0);
    }
}
