//! The path-tracing kernels of `reference`: free flights, shadow transmittance, next-event
//! estimation, and the path loop shared by camera paths and scattering-grid estimates.

use glam::Vec3;
use std::f32::consts::PI;

use super::ReferenceSettings;
use crate::medium::{ray_box, FreeFlight, MajorantGrid, Medium, Tracking};
use crate::phase::{hg, HenyeyGreenstein};
use crate::rng::Rng;
use crate::sampling::{uniform_cone, uniform_sphere};
use crate::scene::{Environment, Light, Scene, SphereInterior};

/// Radiance reaching the camera along one path, split by scattering order.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathRadiance {
    /// Light scattered exactly once (direct lighting at the first vertex).
    pub single: Vec3,
    /// Light scattered two or more times.
    pub multiple: Vec3,
    /// The environment seen through the medium, unscattered.
    pub background: Vec3,
    /// The medium's emission seen directly (camera paths only).
    pub emission: Vec3,
}

impl PathRadiance {
    pub fn add(&mut self, o: &PathRadiance) {
        self.single += o.single;
        self.multiple += o.multiple;
        self.background += o.background;
        self.emission += o.emission;
    }
    pub fn total(&self) -> Vec3 {
        self.single + self.multiple + self.background + self.emission
    }
}

pub struct Tracer<'a> {
    medium: &'a Medium,
    majorant: MajorantGrid,
    lights: &'a [Light],
    env: Option<&'a Environment>,
    phase: HenyeyGreenstein,
    max_depth: u32,
    rr_depth: u32,
}

/// Power heuristic for two strategies with one sample each.
#[inline]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 { a2 / (a2 + b2) } else { 0.0 }
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Scene, s: &ReferenceSettings) -> Self {
        let medium = &scene.medium;
        Tracer {
            medium,
            majorant: MajorantGrid::new(medium, s.majorant_resolution as i32),
            lights: &scene.lights,
            env: scene.environment(),
            phase: HenyeyGreenstein::new(medium.g),
            max_depth: s.max_depth,
            rr_depth: s.rr_depth,
        }
    }

    fn tracking(&self) -> Tracking<'_> {
        Tracking::new(self.medium, &self.majorant)
    }

    /// Free flight from `x` along unit `d` to the medium's end (medium::tracking): the distance
    /// to a real collision, or None if the ray leaves the medium; `beta` takes the weights.
    fn free_flight(&self, x: Vec3, d: Vec3, beta: &mut Vec3, rng: &mut Rng) -> Option<f32> {
        match self.tracking().sample_free_flight(x, d, f32::INFINITY, *beta, rng) {
            FreeFlight::Scattered { t, weight } => {
                *beta = weight;
                Some(t)
            }
            FreeFlight::Escaped { weight } => {
                *beta = weight;
                None
            }
        }
    }

    /// Ratio-tracking estimate of the RGB transmittance from `x` along unit `d` over `t_max`.
    pub fn transmittance(&self, x: Vec3, d: Vec3, t_max: f32, rng: &mut Rng) -> Vec3 {
        self.tracking().ratio_transmittance(x, d, t_max, rng)
    }

    /// Next-event estimation at `x` for a path arriving along propagation direction `d`:
    /// sum over lights of phase * radiance * transmittance / pdf (the phase function is
    /// evaluated for light scattered into -d, i.e. towards where the path came from).
    fn direct_light(&self, x: Vec3, d: Vec3, rng: &mut Rng) -> Vec3 {
        let mut sum = Vec3::ZERO;
        for light in self.lights {
            match light {
                Light::Distant { direction, irradiance, half_angle } => {
                    let to_light = -*direction;
                    let (wi, weight) = if *half_angle > 0.0 {
                        // Uniform disc of radiance E / (pi sin^2), sampled uniformly in its
                        // cone of solid angle 2 pi (1 - cos): weight Omega / (pi sin^2).
                        let s = (0.5 * half_angle).sin();
                        let one_minus_cos = 2.0 * s * s;
                        let sin2 = half_angle.sin().powi(2);
                        (uniform_cone(to_light, one_minus_cos, rng.pair()), 2.0 * one_minus_cos / sin2)
                    } else {
                        (to_light, 1.0)
                    };
                    let ph = hg(wi.dot(d), self.phase.g);
                    sum += *irradiance * weight * ph * self.transmittance(x, wi, f32::INFINITY, rng);
                }
                Light::Point { position, intensity, radius, interior } => {
                    sum += self.point_light(x, d, *position, *intensity, *radius, *interior, rng)
                }
                Light::Spot(spot) => {
                    let from = x - spot.position;
                    let falloff = spot.falloff(from.normalize_or(spot.axis));
                    if falloff > 0.0 {
                        sum += falloff * self.point_light(x, d, spot.position, spot.intensity, spot.radius, SphereInterior::Dark, rng);
                    }
                }
                Light::Area(area) => {
                    // A point uniform in area (pdf 1/A): radiance x cos at the light / dist^2 x A.
                    let p = area.point(rng.pair());
                    let to = p - x;
                    let dist2 = to.length_squared();
                    let cos_l = -area.normal.dot(to);
                    if dist2 > 1e-12 && cos_l > 0.0 {
                        let dist = dist2.sqrt();
                        let wi = to / dist;
                        let ph = hg(wi.dot(d), self.phase.g);
                        let geometry = (cos_l / dist) * area.area() / dist2;
                        sum += area.radiance * geometry * ph * self.transmittance(x, wi, dist, rng);
                    }
                }
                Light::Dome(env) => {
                    let (wi, pdf) = env.sample(rng.pair());
                    if pdf > 0.0 {
                        let ph = hg(wi.dot(d), self.phase.g);
                        let w = power_heuristic(pdf, ph);
                        sum += env.radiance(wi) * ph * w / pdf * self.transmittance(x, wi, f32::INFINITY, rng);
                    }
                }
            }
        }
        sum
    }

    /// Next-event estimate of a point (radius 0) or sphere light of intensity `intensity`: the
    /// sphere's surface has radiance I / (pi r^2); from inside, `interior` decides
    /// (docs/scene-format.md): nothing, or half that radiance from every direction.
    #[allow(clippy::too_many_arguments)]
    fn point_light(&self, x: Vec3, d: Vec3, position: Vec3, intensity: Vec3, radius: f32, interior: SphereInterior, rng: &mut Rng) -> Vec3 {
        let to = position - x;
        let dist2 = to.length_squared();
        let dist = dist2.sqrt();
        if radius > 0.0 && dist > radius {
            // Sampled uniformly in the cone the sphere subtends.
            let sin2 = (radius * radius / dist2).min(1.0);
            let cos_max = (1.0 - sin2).max(0.0).sqrt();
            let one_minus_cos = if sin2 < 1e-4 { 0.5 * sin2 + 0.125 * sin2 * sin2 } else { 1.0 - cos_max };
            let axis = to / dist;
            let wi = uniform_cone(axis, one_minus_cos, rng.pair());
            let solid_angle = 2.0 * PI * one_minus_cos;
            // Distance to the sphere's near surface along wi.
            let b = wi.dot(to);
            let t_hit = b - (b * b - dist2 + radius * radius).max(0.0).sqrt();
            let radiance = intensity / (PI * radius * radius);
            let ph = hg(wi.dot(d), self.phase.g);
            radiance * solid_angle * ph * self.transmittance(x, wi, t_hit.max(0.0), rng)
        } else if radius > 0.0 {
            if interior == SphereInterior::Dark {
                return Vec3::ZERO;
            }
            // Inside a lit sphere: half the surface's radiance from every direction (fluence
            // 2 I / r^2, the surface's own value), uniform over directions, to the surface ahead.
            let wi = uniform_sphere(rng.pair());
            let b = wi.dot(to);
            let t_hit = b + (b * b - dist2 + radius * radius).max(0.0).sqrt();
            let radiance = intensity / (2.0 * PI * radius * radius);
            radiance * (4.0 * PI) * hg(wi.dot(d), self.phase.g) * self.transmittance(x, wi, t_hit, rng)
        } else if dist > 1e-6 {
            let wi = to / dist;
            let ph = hg(wi.dot(d), self.phase.g);
            intensity / dist2 * ph * self.transmittance(x, wi, dist, rng)
        } else {
            Vec3::ZERO
        }
    }

    /// One-sample estimate of the emitted radiance arriving at `x` from direction `-d`:
    /// integral over t of T(x, x + t d) e(x + t d) dt, by a point t uniform on the segment of
    /// the ray inside the emission's bounds (pdf 1 / length), times the ratio-tracked
    /// transmittance to it. Unbiased wherever the emission is, even where the density is zero
    /// (a collision estimator e / sigma_t at real collisions would miss flames in clear air),
    /// and for RGB extinction (e in W m^-3 sr^-1, medium::emission).
    fn emission_along(&self, x: Vec3, d: Vec3, rng: &mut Rng) -> Vec3 {
        let Some(em) = &self.medium.emission else { return Vec3::ZERO };
        let (lo, hi) = em.world_bounds();
        let Some((t0, t1)) = ray_box(x, d, lo, hi) else { return Vec3::ZERO };
        let t = t0 + (t1 - t0) * rng.f32();
        let e = em.at(x + d * t);
        if e.max_element() <= 0.0 {
            return Vec3::ZERO;
        }
        e * (t1 - t0) * self.transmittance(x, d, t, rng)
    }

    /// Radiance escaping to the environment along a phase-sampled direction, MIS-weighted
    /// against the dome's own sampling.
    fn escaped(&self, d: Vec3, pdf_phase: f32) -> Vec3 {
        match self.env {
            Some(env) => env.radiance(d) * power_heuristic(pdf_phase, env.pdf(d)),
            None => Vec3::ZERO,
        }
    }

    /// The random walk from a scattering vertex at `x`, reached along propagation direction
    /// `d`, with throughput `beta` *after* the vertex's albedo. `depth` counts the vertex.
    /// Returns (direct light at this and later vertices by order: first vertex, others).
    fn walk(&self, mut x: Vec3, mut d: Vec3, mut beta: Vec3, mut depth: u32, rng: &mut Rng) -> (Vec3, Vec3) {
        let mut first = Vec3::ZERO;
        let mut later = Vec3::ZERO;
        let albedo = self.medium.albedo;
        loop {
            let ld = beta * self.direct_light(x, d, rng);
            if depth == 1 { first += ld } else { later += ld }
            if depth >= self.max_depth {
                break;
            }
            if depth >= self.rr_depth {
                let q = beta.max_element().min(0.95);
                if q <= 0.0 || rng.f32() >= q {
                    break;
                }
                beta /= q;
            }
            let new_d = self.phase.sample(d, rng.pair());
            let pdf = hg(new_d.dot(d), self.phase.g);
            d = new_d;
            // The medium's emission reaching this vertex along the phase-sampled direction
            // (the phase sample has weight 1, so beta is unchanged).
            if self.medium.emission.is_some() {
                let le = beta * self.emission_along(x, d, rng);
                if depth == 1 { first += le } else { later += le }
            }
            match self.free_flight(x, d, &mut beta, rng) {
                None => {
                    let le = beta * self.escaped(d, pdf);
                    if depth == 1 { first += le } else { later += le }
                    break;
                }
                Some(t) => {
                    x += d * t;
                    depth += 1;
                    beta *= albedo;
                }
            }
            if beta.max_element() <= 0.0 {
                break;
            }
        }
        (first, later)
    }

    /// Radiance along a camera ray from `o` in unit direction `d`.
    pub fn camera_path(&self, o: Vec3, d: Vec3, rng: &mut Rng) -> PathRadiance {
        let emission = self.emission_along(o, d, rng);
        let mut beta = Vec3::ONE;
        match self.free_flight(o, d, &mut beta, rng) {
            None => PathRadiance { background: beta * self.env.map_or(Vec3::ZERO, |e| e.radiance(d)), emission, ..Default::default() },
            Some(t) => {
                let (single, multiple) = self.walk(o + d * t, d, beta * self.medium.albedo, 1, rng);
                PathRadiance { single, multiple, background: Vec3::ZERO, emission }
            }
        }
    }

    /// One-sample estimate of the integral of p * L over incident directions at `x`, for light
    /// leaving towards a viewer along `view` (the propagation direction of the camera ray
    /// through x). Multiplied by sigma_s(x) it is the scattering grid S.
    pub fn in_scattered(&self, x: Vec3, view: Vec3, rng: &mut Rng) -> Vec3 {
        let (first, later) = self.walk(x, view, Vec3::ONE, 1, rng);
        first + later
    }
}
