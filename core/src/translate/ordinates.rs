//! A distant light as one directional ordinate (paper 01, Sec. 4): the light's direction of
//! travel, the fluence it brings and the anisotropy of its angular spread. Domes become many
//! ordinates of the same type (dome.rs).

use glam::Vec3;

/// One distant ordinate: light arriving from a region of directions, as one direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ordinate {
    /// Direction of travel of its light (the negated arriving direction), unit.
    pub direction: Vec3,
    /// Integral of the radiance over its region (W/m^2), RGB.
    pub fluence: Vec3,
    /// Initial anisotropy: the region's (luminance-weighted) mean cosine about the direction.
    pub a0: f32,
    /// Solid angle of its region (sr).
    pub solid_angle: f32,
}

/// A distant light (`Light::Distant`: irradiance E perpendicular to the beam, a disc of
/// uniform radiance of angular radius `half_angle`) as one ordinate. A disc of angular radius
/// theta and irradiance E (perpendicular) has fluence E * 2 / (1 + cos theta) and mean cosine
/// (1 + cos theta) / 2, the initial anisotropy. 1 - cos theta is computed as 2 sin^2(theta/2):
/// for the sun's 0.27 degrees, 1 - cos in f32 loses the angle.
pub fn distant_ordinate(direction: Vec3, irradiance: Vec3, half_angle: f32) -> Ordinate {
    let one_minus_cos = 2.0 * (0.5 * half_angle).sin().powi(2);
    let fluence = irradiance * (2.0 / (2.0 - one_minus_cos));
    Ordinate { direction, fluence, a0: 1.0 - 0.5 * one_minus_cos, solid_angle: 2.0 * std::f32::consts::PI * one_minus_cos }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the closed forms in double precision: the fluence is the integral of the disc's
    /// radiance L = E / (pi sin^2 theta) over its solid angle 2 pi (1 - cos theta), and a0 the
    /// solid-angle mean cosine (1 + cos theta) / 2; a delta light (theta = 0) has fluence E and
    /// a0 = 1. Tolerance 1e-5 relative: f32 rounding.
    #[test]
    fn distant_ordinate_matches_the_disc() {
        let e = Vec3::new(3.0, 2.0, 1.0);
        let delta = distant_ordinate(Vec3::Z, e, 0.0);
        assert_eq!((delta.fluence, delta.a0, delta.solid_angle), (e, 1.0, 0.0));
        for deg in [0.27f64, 5.0, 30.0] {
            let t = deg.to_radians();
            let o = distant_ordinate(-Vec3::Z, e, t as f32);
            let radiance = 1.0 / (std::f64::consts::PI * t.sin().powi(2));
            let fluence = radiance * 2.0 * std::f64::consts::PI * (1.0 - t.cos());
            assert!((o.fluence.x as f64 / 3.0 / fluence - 1.0).abs() < 1e-5, "{deg}: {} vs {fluence}", o.fluence.x / 3.0);
            assert!((o.a0 as f64 - (1.0 + t.cos()) / 2.0).abs() < 1e-6, "{deg}: a0 {}", o.a0);
            assert!((o.solid_angle as f64 / (2.0 * std::f64::consts::PI * (1.0 - t.cos())) - 1.0).abs() < 1e-5);
        }
    }
}
