//! Light sampling: rays drawn from the scene's lights, each carrying a share of their power,
//! where photon tracing (paper 04) and VPL random walks (paper 03) start.
//!
//! `LightSampler::new` looks at the scene once; `sample` then turns six uniforms into a ray
//! (origin, direction of travel, RGB power) from one light. A light is chosen with probability
//! proportional to its power (the sum of its RGB channels; a discrete CDF in f64), and the
//! ray's power is divided by that probability, so for N rays sum(power) / N is an unbiased
//! estimate of the scene's total power and of each light's (tallied by `LightRay::light`).
//!
//! Per light (units of docs/scene-format.md; P is the power the light contributes):
//! - distant (irradiance E perpendicular to the beam, angular radius theta): directions
//!   uniform in the cone of half-angle theta about its direction (its radiance is uniform over
//!   the disc of the source); the origin uniform on the disc of the medium's bounding sphere
//!   (centre c, radius R) perpendicular to *that ray's* direction, on the sphere's near side,
//!   c - R w + a point of the disc. Every ray can reach the sphere and none that could is
//!   missed, so P = pi R^2 x the fluence E 2 / (1 + cos theta) (pi R^2 E for a delta light):
//!   the power the sphere intercepts, which is what reaches the medium.
//! - dome: directions by the map's importance (`Environment::sample`: luminance x solid
//!   angle), the origin on the bounding disc perpendicular to the ray as for a distant light;
//!   power pi R^2 L(w) / pdf(w), so P = pi R^2 x the dome's fluence (`dome::dome_fluence`).
//! - point (radius 0): from its position, directions uniform, P = 4 pi I.
//! - sphere (a point with radius r > 0, uniform radiance I / (pi r^2)): origins uniform on its
//!   surface, directions cosine-weighted about the outward normal, P = 4 pi I.
//! - spot: directions by its profile (`Profile::Cone`: full inside the inner cone, the
//!   smoothstep blend between inner and outer, sampled exactly by inverting the blend's CDF
//!   2t^3 - t^4), P = I x `Profile::solid_angle`. With a radius the ray starts where it leaves
//!   the sphere, position + r w: the same intensity pattern from outside the sphere.
//! - rect and disk: origins uniform over the area (`AreaLight::point`), directions
//!   cosine-weighted about the normal, P = pi L A.
//! - emissive medium: a trilinear cell (`EmissionTerm::for_each_emitting_cell`) chosen by its
//!   power 4 pi e dV (translate/emission.rs's cells), the origin uniform inside it, the
//!   direction uniform; P = `Emission::power()`. Departure: within a cell the emission is
//!   trilinear, taken here as uniform, so positions are exact to one voxel.
//!
//! Uniforms: u[0] chooses the light (and, rescaled, the emissive cell), u[1..4] the position,
//! u[4..6] the direction; the same uniforms give the same ray (`sample_rng` draws them from a
//! `crate::rng::Rng`).

use glam::{IVec3, Vec3};
use std::f32::consts::PI;

use super::dome::dome_fluence;
use super::ordinates::distant_ordinate;
use super::Profile;
use crate::medium::Medium;
use crate::rng::Rng;
use crate::sampling::{cosine_hemisphere, orthonormal_basis, uniform_cone, uniform_sphere, DiscreteDistribution};
use crate::sampling::concentric_disk;
use crate::scene::light::{AreaLight, Spot};
use crate::scene::{Environment, Light, Scene};

/// One ray leaving a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightRay {
    pub origin: Vec3,
    /// Direction of travel, unit.
    pub direction: Vec3,
    /// Power carried (W, RGB), already divided by the probability of drawing this ray: the
    /// mean over rays is the scene's total power.
    pub power: Vec3,
    /// Index of the light in `scene.lights`, or `scene.lights.len()` for the emissive medium.
    pub light: usize,
}

/// The sphere around the medium's world box from which distant lights and domes shine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingSphere {
    pub center: Vec3,
    pub radius: f32,
}

impl BoundingSphere {
    pub fn of(medium: &Medium) -> Self {
        let (lo, hi) = medium.world_bounds();
        BoundingSphere { center: 0.5 * (lo + hi), radius: (0.5 * (hi - lo).length()).max(1e-6) }
    }

    /// The origin of a ray travelling along `w` through the disc of the sphere perpendicular
    /// to it, on the sphere's near side, for `u` uniform on the disc.
    fn disc_origin(&self, w: Vec3, u: [f32; 2]) -> Vec3 {
        let (t, b) = orthonormal_basis(w);
        let (x, y) = concentric_disk(u);
        self.center + (t * x + b * y - w) * self.radius
    }

    fn disc_area(&self) -> f32 {
        PI * self.radius * self.radius
    }
}

/// An emitting trilinear cell: `ijk` of term `term`, its power 4 pi e dV.
struct EmittingCell {
    term: u32,
    ijk: IVec3,
    power: Vec3,
}

enum Source<'a> {
    /// `one_minus_cos` of the angular radius, as 2 sin^2(theta / 2) (ordinates.rs).
    Distant { direction: Vec3, one_minus_cos: f32 },
    Dome(&'a Environment),
    Point { position: Vec3, radius: f32 },
    Spot(Spot),
    Area(AreaLight),
    Emission { cells: Vec<EmittingCell>, choice: DiscreteDistribution },
}

/// Rays with their power from every light of a scene (see the module doc).
pub struct LightSampler<'a> {
    medium: &'a Medium,
    sphere: BoundingSphere,
    /// (light index, source, its power).
    sources: Vec<(usize, Source<'a>, Vec3)>,
    choice: DiscreteDistribution,
}

impl<'a> LightSampler<'a> {
    pub fn new(scene: &'a Scene) -> Self {
        let medium = &scene.medium;
        let sphere = BoundingSphere::of(medium);
        let mut sources = Vec::new();
        for (i, light) in scene.lights.iter().enumerate() {
            let (source, power) = match light {
                Light::Distant { direction, irradiance, half_angle } => {
                    let fluence = distant_ordinate(*direction, *irradiance, *half_angle).fluence;
                    let one_minus_cos = 2.0 * (0.5 * half_angle).sin().powi(2);
                    (Source::Distant { direction: direction.normalize(), one_minus_cos }, fluence * sphere.disc_area())
                }
                Light::Dome(env) => (Source::Dome(env), dome_fluence(env) * sphere.disc_area()),
                Light::Point { position, intensity, radius, .. } => (Source::Point { position: *position, radius: *radius }, *intensity * (4.0 * PI)),
                Light::Spot(s) => (Source::Spot(*s), s.intensity * cone_profile(s).solid_angle()),
                Light::Area(a) => (Source::Area(*a), a.power()),
            };
            sources.push((i, source, power));
        }
        if let Some(emission) = &medium.emission {
            let mut cells = Vec::new();
            for (t, term) in emission.terms.iter().enumerate() {
                let dv = term.voxel_volume();
                term.for_each_emitting_cell(|ijk, e| cells.push(EmittingCell { term: t as u32, ijk, power: e * (4.0 * PI * dv) }));
            }
            let choice = DiscreteDistribution::new(cells.iter().map(|c| c.power.element_sum() as f64));
            let power = cells.iter().map(|c| c.power.as_dvec3()).sum::<glam::DVec3>().as_vec3();
            sources.push((scene.lights.len(), Source::Emission { cells, choice }, power));
        }
        let choice = DiscreteDistribution::new(sources.iter().map(|(_, _, p)| p.element_sum() as f64));
        LightSampler { medium, sphere, sources, choice }
    }

    /// The sphere distant lights and domes shine from.
    pub fn bounding_sphere(&self) -> BoundingSphere {
        self.sphere
    }

    /// Total power of every light (W, RGB): the expected `LightRay::power`.
    pub fn total_power(&self) -> Vec3 {
        self.sources.iter().map(|(_, _, p)| *p).sum()
    }

    /// The power of light `light` (an index as in `LightRay::light`); zero if it has none.
    pub fn light_power(&self, light: usize) -> Vec3 {
        self.sources.iter().filter(|(i, _, _)| *i == light).map(|(_, _, p)| *p).sum()
    }

    /// True when no light emits anything: `sample` returns None.
    pub fn is_empty(&self) -> bool {
        self.choice.sample(0.5).is_none()
    }

    /// A ray for the uniforms `u` (layout in the module doc); None when no light emits.
    pub fn sample(&self, u: [f32; 6]) -> Option<LightRay> {
        let (k, p_light, u_rest) = self.choice.sample(u[0])?;
        let (light, source, _) = &self.sources[k];
        let pos = [u[1], u[2]];
        let dir = [u[4], u[5]];
        let (origin, direction, power) = match source {
            Source::Distant { direction, one_minus_cos } => {
                let w = if *one_minus_cos > 0.0 { uniform_cone(*direction, *one_minus_cos, dir) } else { *direction };
                (self.sphere.disc_origin(w, pos), w, self.sources[k].2)
            }
            Source::Dome(env) => {
                let (sky, pdf) = env.sample(dir);
                let power = if pdf > 0.0 { env.radiance(sky) * (self.sphere.disc_area() / pdf) } else { Vec3::ZERO };
                (self.sphere.disc_origin(-sky, pos), -sky, power)
            }
            Source::Point { position, radius } => {
                if *radius > 0.0 {
                    let n = uniform_sphere(pos);
                    (*position + n * *radius, cosine_hemisphere(n, dir), self.sources[k].2)
                } else {
                    (*position, uniform_sphere(dir), self.sources[k].2)
                }
            }
            Source::Spot(s) => {
                let w = sample_cone_profile(s, dir);
                (s.position + w * s.radius, w, self.sources[k].2)
            }
            Source::Area(a) => (a.point(pos), cosine_hemisphere(a.normal, dir), self.sources[k].2),
            Source::Emission { cells, choice } => {
                let (c, p_cell, _) = choice.sample(u_rest)?;
                let cell = &cells[c];
                let term = &self.medium.emission.as_ref()?.terms[cell.term as usize];
                let local = cell.ijk.as_vec3() + Vec3::new(u[1], u[2], u[3]);
                (term.index_to_world.transform_point3(local), uniform_sphere(dir), cell.power / p_cell as f32)
            }
        };
        Some(LightRay { origin, direction, power: power / p_light as f32, light: *light })
    }

    /// `sample` with its six uniforms drawn from `rng`.
    pub fn sample_rng(&self, rng: &mut Rng) -> Option<LightRay> {
        let u = [rng.f32(), rng.f32(), rng.f32(), rng.f32(), rng.f32(), rng.f32()];
        self.sample(u)
    }
}

/// A spot's angular profile (the same as its point emitter's, translate::spot_emitter).
fn cone_profile(s: &Spot) -> Profile {
    Profile::Cone { axis: s.axis, cos_outer: s.cos_outer, cos_inner: s.cos_inner }
}

/// A direction with density proportional to the spot's falloff smoothstep(cos_outer,
/// cos_inner, cos theta). Solid angle is uniform in cos theta, so: the cap inside the inner
/// cone (full intensity) is drawn with probability cap / (cap + band / 2), where cap =
/// 1 - cos_inner and band = cos_inner - cos_outer, uniform in cos theta; otherwise the blend
/// band, where t = (cos theta - cos_outer) / band has density 2 smoothstep(t) = 6t^2 - 4t^3
/// and CDF 2t^3 - t^4, inverted by bisection (it is monotone). u[0] picks the part and then
/// the angle.
fn sample_cone_profile(s: &Spot, u: [f32; 2]) -> Vec3 {
    let axis = s.axis.normalize();
    let cap = (1.0 - s.cos_inner).max(0.0);
    let band = (s.cos_inner - s.cos_outer).max(0.0);
    let p_cap = cap / (cap + 0.5 * band);
    let cos_t = if u[0] < p_cap || band <= 0.0 {
        1.0 - (u[0] / p_cap).min(1.0) * cap
    } else {
        let v = ((u[0] - p_cap) / (1.0 - p_cap)).clamp(0.0, 1.0);
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..24 {
            let t = 0.5 * (lo + hi);
            if 2.0 * t * t * t - t * t * t * t < v { lo = t } else { hi = t }
        }
        s.cos_outer + 0.5 * (lo + hi) * band
    };
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    let (t, b) = orthonormal_basis(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

#[cfg(test)]
mod tests;
