//! Point emitters: point, sphere and spot lights, and rect/disk area lights, as a position, an
//! intensity and an angular profile. A point or spot light is one emitter; an area light is a
//! set of virtual point lights (VPLs) spread over its surface, each with a share of the area and
//! the Lambertian (cosine) profile, so the set has the light's power and, from further than the
//! spacing of the VPLs, its intensity in every direction.

use glam::Vec3;

use crate::scene::light::{AreaLight, SphereInterior, Spot};
use super::emission;
use crate::scene::{Light, Scene};

/// How a point emitter's intensity depends on the direction w (unit, away from it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Profile {
    Isotropic,
    /// smoothstep(cos_outer, cos_inner, w . axis), as `Spot::falloff`.
    Cone { axis: Vec3, cos_outer: f32, cos_inner: f32 },
    /// max(0, w . normal): a patch of a Lambertian emitter.
    Cosine { normal: Vec3 },
}

impl Profile {
    pub fn factor(&self, w: Vec3) -> f32 {
        match *self {
            Profile::Isotropic => 1.0,
            Profile::Cone { axis, cos_outer, cos_inner } => crate::scene::light::smoothstep(cos_outer, cos_inner, w.dot(axis)),
            Profile::Cosine { normal } => w.dot(normal).max(0.0),
        }
    }

    /// Mean cosine of the emitted light about `axis()` (the anisotropy a radial grid starts
    /// with): 0 for isotropic, 2/3 for the cosine lobe, the cone's for a spot.
    pub fn mean_cosine(&self) -> f32 {
        match *self {
            Profile::Isotropic => 0.0,
            Profile::Cosine { .. } => 2.0 / 3.0,
            Profile::Cone { cos_outer, cos_inner, .. } => {
                // The cone's average of cos theta, weighted by the falloff: a 256-step
                // quadrature in cos theta (solid angle is uniform in it).
                let (mut w_sum, mut c_sum) = (0.0f32, 0.0f32);
                for i in 0..256 {
                    let c = -1.0 + (i as f32 + 0.5) / 128.0;
                    let f = crate::scene::light::smoothstep(cos_outer, cos_inner, c);
                    w_sum += f;
                    c_sum += f * c;
                }
                if w_sum > 0.0 { c_sum / w_sum } else { 0.0 }
            }
        }
    }

    /// The profile's axis (Z for isotropic).
    pub fn axis(&self) -> Vec3 {
        match *self {
            Profile::Isotropic => Vec3::Z,
            Profile::Cone { axis, .. } => axis,
            Profile::Cosine { normal } => normal,
        }
    }

    /// The profile's integral over the sphere (sr): power = intensity x this.
    pub fn solid_angle(&self) -> f32 {
        use std::f32::consts::PI;
        match *self {
            Profile::Isotropic => 4.0 * PI,
            Profile::Cosine { .. } => PI,
            Profile::Cone { cos_outer, cos_inner, .. } => {
                // Exact: 2 pi (1 - cos_inner) + 2 pi x (the smoothstep's mean over the blend
                // band, 1/2) x its width.
                2.0 * PI * ((1.0 - cos_inner) + 0.5 * (cos_inner - cos_outer).max(0.0))
            }
        }
    }
}

/// A point light as the solvers see it: intensity(w) = `intensity` x `profile.factor(w)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointEmitter {
    pub position: Vec3,
    /// W/sr at the profile's peak.
    pub intensity: Vec3,
    /// > 0: a sphere light of this radius (solvers may treat it as a point from outside it).
    pub radius: f32,
    /// What that radius is: a sphere lamp's surface, or a ball the light is spread over.
    pub extent: Extent,
    pub profile: Profile,
}

/// What a `PointEmitter`'s radius > 0 stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Extent {
    /// A sphere lamp's surface (docs/scene-format.md "Sphere lamps"), with what its inside gets.
    Sphere(SphereInterior),
    /// A ball its light is spread over (an emission VPL's stratum, translate::emission): 1/d^2
    /// as its mean over the ball.
    Ball,
}

impl PointEmitter {
    pub fn intensity_towards(&self, w: Vec3) -> Vec3 {
        self.intensity * self.profile.factor(w)
    }

    /// The emitter's field at distance `d` per W/sr, spread over `near`: a sphere lamp's
    /// (`medium::lamp_inverse_square`) or the mean of 1/d^2 over its ball.
    #[inline]
    pub fn inverse_square(&self, d: f32, near: f32) -> f32 {
        match self.extent {
            Extent::Sphere(interior) => crate::medium::lamp_inverse_square(d, self.radius, near, interior == SphereInterior::Lit),
            Extent::Ball => crate::medium::ball_mean_inverse_square(d, (self.radius * self.radius + near * near).sqrt()),
        }
    }

    /// `inverse_square` as a cell's mean: a sphere lamp larger than `near` is averaged over the
    /// ball of radius `near` about the point (`medium::lamp_mean_over_ball`), as a smaller one
    /// already is.
    pub fn cell_mean_inverse_square(&self, d: f32, near: f32) -> f32 {
        match self.extent {
            Extent::Sphere(interior) if self.radius > near => crate::medium::lamp_mean_over_ball(d, self.radius, near, interior == SphereInterior::Lit),
            _ => self.inverse_square(d, near),
        }
    }

    /// How far the light from this emitter travels through the medium to a point at distance
    /// `d`, along the direction to its centre: a sphere lamp's light leaves its surface; inside
    /// a lit lamp it comes from every direction, taken as the mean chord to the surface,
    /// r - d^2 / 3r (Jensen: slightly dark; the lamp probe states by how much); a point's or a
    /// ball's light, from its centre.
    #[inline]
    pub fn shadow_length(&self, d: f32) -> f32 {
        match self.extent {
            Extent::Sphere(_) if d < self.radius => self.radius - d * d / (3.0 * self.radius),
            Extent::Sphere(_) => d - self.radius,
            Extent::Ball => d,
        }
    }

    pub fn power(&self) -> Vec3 {
        self.intensity * self.profile.solid_angle()
    }

    /// The directions a sphere lamp's light reaches `x` from, `n` of them even in solid angle
    /// (a Fibonacci spiral): over the cap the lamp subtends from outside it, over every
    /// direction inside a lit one. Each comes with the distance to the surface along it and its
    /// share of the field, the shares summing to `inverse_square(d, 0)`. Empty for anything but
    /// a sphere lamp, and inside a dark one. Why: light near an optically thick lamp crosses
    /// the medium along each of these, and the direction to the centre alone crosses less of it.
    pub fn sphere_directions(&self, x: Vec3, n: u32) -> Vec<(Vec3, f32, f32)> {
        let Extent::Sphere(interior) = self.extent else { return Vec::new() };
        let to = self.position - x;
        let (d2, r2) = (to.length_squared(), self.radius * self.radius);
        let d = d2.sqrt();
        let outside = d > self.radius;
        if self.radius <= 0.0 || n == 0 || (!outside && interior == SphereInterior::Dark) {
            return Vec::new();
        }
        // Outside: the cap of half-angle asin(r / d), radiance 1 / (pi r^2) per W/sr; inside a
        // lit lamp: every direction, half that radiance (docs/scene-format.md, sphere lamps).
        let (axis, one_minus_cos, radiance) = if outside {
            let sin2 = r2 / d2;
            let omc = if sin2 < 1e-4 { 0.5 * sin2 + 0.125 * sin2 * sin2 } else { 1.0 - (1.0 - sin2).sqrt() };
            (to / d, omc, 1.0 / (std::f32::consts::PI * r2))
        } else {
            (Vec3::Z, 2.0, 0.5 / (std::f32::consts::PI * r2))
        };
        let share = radiance * 2.0 * std::f32::consts::PI * one_minus_cos / n as f32;
        let (u, v) = axis.any_orthonormal_pair();
        (0..n)
            .map(|j| {
                let cos = 1.0 - one_minus_cos * (j as f32 + 0.5) / n as f32;
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = j as f32 * GOLDEN_ANGLE;
                let w = axis * cos + (u * phi.cos() + v * phi.sin()) * sin;
                let b = w.dot(to);
                let root = (b * b - d2 + r2).max(0.0).sqrt();
                // The near side of the surface from outside, the far side from inside.
                let t = if outside { b - root } else { b + root };
                (w, t.max(0.0), share)
            })
            .collect()
    }
}

/// The golden angle, 2 pi (2 - phi), in radians: a Fibonacci spiral's turn per point.
const GOLDEN_ANGLE: f32 = 2.399_963_2;

pub fn spot_emitter(s: &Spot) -> PointEmitter {
    PointEmitter {
        position: s.position,
        intensity: s.intensity,
        radius: s.radius,
        extent: Extent::Sphere(SphereInterior::Dark),
        profile: Profile::Cone { axis: s.axis, cos_outer: s.cos_outer, cos_inner: s.cos_inner },
    }
}

/// An area light as `k x k` VPLs, one at the centre of each stratum of equal area (the disc's
/// strata through the concentric map), each with intensity radiance x area / k^2 along the
/// normal and the cosine profile. Their total power equals the light's exactly.
pub fn area_vpls(a: &AreaLight, k: u32) -> Vec<PointEmitter> {
    let k = k.max(1);
    let share = a.radiance * (a.area() / (k * k) as f32);
    let mut out = Vec::with_capacity((k * k) as usize);
    for j in 0..k {
        for i in 0..k {
            let u = [(i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32];
            out.push(PointEmitter { position: a.point(u), intensity: share, radius: 0.0, extent: Extent::Sphere(SphereInterior::Dark), profile: Profile::Cosine { normal: a.normal } });
        }
    }
    out
}

/// Every point, sphere, spot and area light of `lights` as point emitters; area lights as
/// `area_vpls(_, area_k)`. Distant lights and domes are not point emitters and are skipped.
pub fn local_emitters(lights: &[Light], area_k: u32) -> Vec<PointEmitter> {
    let mut out = Vec::new();
    for light in lights {
        match light {
            Light::Point { position, intensity, radius, interior } => {
                out.push(PointEmitter { position: *position, intensity: *intensity, radius: *radius, extent: Extent::Sphere(*interior), profile: Profile::Isotropic })
            }
            Light::Spot(s) => out.push(spot_emitter(s)),
            Light::Area(a) => out.extend(area_vpls(a, area_k)),
            Light::Distant { .. } | Light::Dome(_) => {}
        }
    }
    out
}

/// Every point emitter of the scene: `local_emitters(lights, area_k)`, then the emissive
/// medium's VPLs (`emission::emission_vpls`, as many as `medium.emission.vpl_count`).
pub fn scene_emitters(scene: &Scene, area_k: u32) -> Vec<PointEmitter> {
    let mut out = local_emitters(&scene.lights, area_k);
    if let Some(e) = &scene.medium.emission {
        out.extend(emission::emission_vpls(&scene.medium, e.vpl_count).emitters);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::light::AreaShape;
    use crate::sampling::uniform_sphere;

    /// A sphere lamp's directions: their shares sum to its field outside it and inside a lit
    /// one, each direction reaches the surface at the distance given, and a dark lamp's inside
    /// and a point lamp have none.
    #[test]
    fn sphere_directions_add_up_to_the_field() {
        let lamp = |interior| PointEmitter { position: Vec3::new(0.2, -0.1, 0.3), intensity: Vec3::ONE, radius: 0.5, extent: Extent::Sphere(interior), profile: Profile::Isotropic };
        for (interior, x) in [(SphereInterior::Dark, Vec3::new(1.5, 0.4, -0.2)), (SphereInterior::Lit, Vec3::new(0.9, -0.1, 0.3)), (SphereInterior::Lit, Vec3::new(0.3, 0.0, 0.1))] {
            let e = lamp(interior);
            let dirs = e.sphere_directions(x, 64);
            let sum: f32 = dirs.iter().map(|d| d.2).sum();
            let field = e.inverse_square((e.position - x).length(), 0.0);
            assert!((sum / field - 1.0).abs() < 1e-4, "{interior:?} at {x}: {sum} vs {field}");
            for (w, t, _) in dirs {
                let on = (x + w * t - e.position).length();
                assert!((on - e.radius).abs() < 1e-4, "{w} {t}: {on}");
            }
        }
        assert!(lamp(SphereInterior::Dark).sphere_directions(Vec3::new(0.3, 0.0, 0.1), 16).is_empty());
        let point = PointEmitter { radius: 0.0, ..lamp(SphereInterior::Lit) };
        assert!(point.sphere_directions(Vec3::ONE, 16).is_empty());
    }

    /// Monte Carlo integral of a profile over the sphere (stratified), to check solid_angle.
    fn integrate(p: &Profile) -> f32 {
        let k = 400;
        let mut s = 0.0;
        for i in 0..k {
            for j in 0..k {
                s += p.factor(uniform_sphere([(i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32]));
            }
        }
        s * 4.0 * std::f32::consts::PI / (k * k) as f32
    }

    #[test]
    fn profile_solid_angles_match_their_integrals() {
        let axis = Vec3::new(0.3, -0.2, 0.9).normalize();
        for p in [
            Profile::Isotropic,
            Profile::Cosine { normal: axis },
            Profile::Cone { axis, cos_outer: 0.5, cos_inner: 0.8 },
            Profile::Cone { axis, cos_outer: 0.9, cos_inner: 0.9 },
        ] {
            let (exact, mc) = (p.solid_angle(), integrate(&p));
            // 160,000 stratified directions: error well under 0.5%.
            assert!((exact - mc).abs() < 5e-3 * exact, "{p:?}: {exact} vs {mc}");
        }
        assert!((Profile::Cosine { normal: axis }.mean_cosine() - 2.0 / 3.0).abs() < 1e-6);
        let narrow = Profile::Cone { axis, cos_outer: 0.95, cos_inner: 0.99 }.mean_cosine();
        assert!(narrow > 0.95 && narrow < 0.99, "{narrow}");
    }

    #[test]
    fn area_vpls_keep_the_power() {
        let a = AreaLight { center: Vec3::ZERO, normal: Vec3::Z, tangent: Vec3::X, shape: AreaShape::Disk { radius: 0.5 }, radiance: Vec3::new(1.0, 2.0, 3.0) };
        let total: Vec3 = area_vpls(&a, 5).iter().map(PointEmitter::power).sum();
        assert!((total - a.power()).abs().max_element() < 1e-4 * a.power().max_element(), "{total} vs {}", a.power());
    }
}
