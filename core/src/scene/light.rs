//! Lights in the units of DESIGN.md, after host conventions have been converted.

use glam::Vec3;

use super::environment::Environment;
use crate::sampling::orthonormal_basis;

#[derive(Clone, Debug)]
pub enum Light {
    /// Light travelling along `direction` (unit), irradiance `irradiance` (W/m^2) on a plane
    /// perpendicular to it, from a disc of uniform radiance of angular radius `half_angle`
    /// (radians; 0 = a delta direction). The angle is kept, not its cosine: for the sun's
    /// 0.27 degrees, 1 - cos in f32 has a 1% error.
    Distant { direction: Vec3, irradiance: Vec3, half_angle: f32 },
    /// Intensity in W/sr. With `radius` > 0: a sphere whose surface has the uniform radiance
    /// I / (pi r^2) outwards, which has the same power 4 pi I and looks the same from afar;
    /// `interior` says what points inside the sphere receive (docs/scene-format.md).
    Point { position: Vec3, intensity: Vec3, radius: f32, interior: SphereInterior },
    /// A point (or sphere) light whose intensity is shaped by a cone: see `Spot`.
    Spot(Spot),
    /// A one-sided rectangle or disc of uniform radiance: see `AreaLight`.
    Area(AreaLight),
    Dome(Environment),
}

/// What a sphere lamp gives points inside its sphere. Outside, every model sees the surface's
/// radiance I / (pi r^2) over the solid angle it subtends.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SphereInterior {
    /// Nothing: the surface emits outwards only (UsdLux SphereLight, Mitsuba's sphere emitter),
    /// so the lamp's power is exactly 4 pi I.
    #[default]
    Dark,
    /// Half the surface's radiance from every direction (fluence 2 I / r^2, the surface's own
    /// value): what Cycles gives points inside a point lamp of non-zero radius (measured on the
    /// benchmark's smoke_point; Blender exports this). Light added inside the sphere.
    Lit,
}

/// Intensity `intensity` (W/sr) along `axis`, I(w) = intensity * smoothstep(cos_outer,
/// cos_inner, w . axis) for the direction w from the light: zero outside the cone of half-angle
/// acos(cos_outer), full inside acos(cos_inner), a smooth blend between (Cycles' spot shape, in
/// the cosine of the angle). `radius` > 0: a sphere light of that radius with the same shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spot {
    pub position: Vec3,
    pub axis: Vec3,
    pub intensity: Vec3,
    pub radius: f32,
    pub cos_outer: f32,
    pub cos_inner: f32,
}

impl Spot {
    /// The fraction of the axis intensity emitted along unit direction `w` (from the light).
    pub fn falloff(&self, w: Vec3) -> f32 {
        smoothstep(self.cos_outer, self.cos_inner, w.dot(self.axis))
    }
}

/// Hermite smoothstep; a step at `e0` when the edges coincide (a hard-edged cone).
pub fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    if e1 <= e0 {
        return if x > e0 { 1.0 } else { 0.0 };
    }
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AreaShape {
    /// `width` along the light's tangent, `height` along normal x tangent.
    Rect { width: f32, height: f32 },
    Disk { radius: f32 },
}

/// A flat emitter of uniform radiance `radiance` (W/m^2/sr) leaving its front face (the side
/// `normal` points to), Lambertian: intensity radiance * area * cos towards a direction at
/// angle theta from the normal, power pi * radiance * area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub center: Vec3,
    pub normal: Vec3,
    /// Unit, perpendicular to `normal`: the rectangle's width direction.
    pub tangent: Vec3,
    pub shape: AreaShape,
    pub radiance: Vec3,
}

impl AreaLight {
    pub fn area(&self) -> f32 {
        match self.shape {
            AreaShape::Rect { width, height } => width * height,
            AreaShape::Disk { radius } => std::f32::consts::PI * radius * radius,
        }
    }

    /// Total emitted power per channel (W).
    pub fn power(&self) -> Vec3 {
        self.radiance * (std::f32::consts::PI * self.area())
    }

    /// The point of the surface for `u` in [0,1)^2, uniform in area (pdf 1 / area). The disc
    /// uses the concentric map, so strata of the square stay compact on the disc.
    pub fn point(&self, u: [f32; 2]) -> Vec3 {
        let bitangent = self.normal.cross(self.tangent);
        let (a, b) = match self.shape {
            AreaShape::Rect { width, height } => ((u[0] - 0.5) * width, (u[1] - 0.5) * height),
            AreaShape::Disk { radius } => {
                let (x, y) = crate::sampling::concentric_disk(u);
                (x * radius, y * radius)
            }
        };
        self.center + self.tangent * a + bitangent * b
    }
}

/// A unit tangent perpendicular to `normal`: `hint` made orthogonal, or any perpendicular when
/// the hint is (nearly) parallel to the normal.
pub fn tangent_for(normal: Vec3, hint: Option<Vec3>) -> Vec3 {
    if let Some(h) = hint {
        let t = h - normal * h.dot(normal);
        if t.length() > 1e-4 {
            return t.normalize();
        }
    }
    orthonormal_basis(normal).0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothstep_edges() {
        assert_eq!(smoothstep(0.5, 0.8, 0.4), 0.0);
        assert_eq!(smoothstep(0.5, 0.8, 0.9), 1.0);
        assert!((smoothstep(0.5, 0.8, 0.65) - 0.5).abs() < 1e-6);
        assert_eq!(smoothstep(0.5, 0.5, 0.51), 1.0);
        assert_eq!(smoothstep(0.5, 0.5, 0.49), 0.0);
    }

    #[test]
    fn area_points_cover_the_shape_uniformly() {
        let n = Vec3::new(0.0, 0.0, -1.0);
        let rect = AreaLight { center: Vec3::ONE, normal: n, tangent: Vec3::X, shape: AreaShape::Rect { width: 2.0, height: 0.5 }, radiance: Vec3::ONE };
        let disk = AreaLight { shape: AreaShape::Disk { radius: 0.7 }, ..rect };
        assert!((disk.area() - std::f32::consts::PI * 0.49).abs() < 1e-6);
        let mut mean = Vec3::ZERO;
        let k = 64;
        for i in 0..k {
            for j in 0..k {
                let u = [(i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32];
                let p = rect.point(u) - rect.center;
                assert!(p.z.abs() < 1e-6 && p.x.abs() <= 1.0 && p.y.abs() <= 0.25, "{p}");
                let q = disk.point(u) - disk.center;
                assert!(q.z.abs() < 1e-6 && q.length() <= 0.7 + 1e-5, "{q}");
                mean += q;
            }
        }
        // The concentric map is uniform: the mean of a symmetric grid of strata is the centre.
        assert!((mean / (k * k) as f32).length() < 1e-4);
        assert!((rect.power() - Vec3::splat(std::f32::consts::PI)).abs().max_element() < 1e-5);
    }
}
