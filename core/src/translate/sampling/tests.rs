//! Light sampling against closed forms: per light type (a) the mean ray power equals the
//! light's power, (b) directions follow its profile (chi-square at the 99.9% quantile),
//! (c) rays start where they should (on the light, or on the bounding sphere's disc).
//!
//! Mean power: rays of one light all carry the same power except for domes and emissive
//! media, so the check is "within 5 standard errors of the mean, plus 1e-5 relative for f32
//! rounding"; the standard error is measured from the same rays.

use super::*;
use crate::medium::{Emission, EmissionLaw, EmissionTerm};
use crate::sampling::{chi_square, chi_square_pooled, chi_square_quantile_999};
use crate::scene::{AreaShape, LatLongMap};

const N: usize = 200_000;

fn scene_with(lights: Vec<Light>) -> Scene {
    let mut s = Scene::default_scene();
    s.lights = lights;
    s.medium.emission = None;
    s
}

fn rays(sampler: &LightSampler, n: usize, seed: u64) -> Vec<LightRay> {
    let mut rng = Rng::new(seed, 0);
    (0..n).map(|_| sampler.sample_rng(&mut rng).expect("a light with power")).collect()
}

/// Mean and standard error of the mean, per channel, of the rays' power.
fn mean_and_se(rays: &[LightRay]) -> (glam::DVec3, glam::DVec3) {
    let n = rays.len() as f64;
    let (mut s, mut s2) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    for r in rays {
        let p = r.power.as_dvec3();
        s += p;
        s2 += p * p;
    }
    let mean = s / n;
    let var = (s2 / n - mean * mean).max(glam::DVec3::ZERO) * (n / (n - 1.0));
    (mean, (var / n).map(f64::sqrt))
}

fn assert_mean_power(rays: &[LightRay], expected: Vec3, what: &str) {
    let (mean, se) = mean_and_se(rays);
    let e = expected.as_dvec3();
    let bound = se * 5.0 + e.abs() * 1e-5;
    assert!((mean - e).abs().cmple(bound).all(), "{what}: mean power {mean} vs {e} (5 SE + 1e-5: {bound})");
}

/// Chi-square of `values` in [0, 1) against `probs` over equal-width bins.
fn chi2_of(values: impl Iterator<Item = f32>, probs: &[f64]) -> f64 {
    let bins = probs.len();
    let mut counts = vec![0u64; bins];
    for v in values {
        counts[((v * bins as f32) as usize).min(bins - 1)] += 1;
    }
    chi_square(&counts, probs)
}

fn assert_uniform(values: impl Iterator<Item = f32>, bins: usize, what: &str) {
    let chi2 = chi2_of(values, &vec![1.0 / bins as f64; bins]);
    assert!(chi2 < chi_square_quantile_999(bins - 1), "{what}: chi-square {chi2} over {} dof", bins - 1);
}

/// Angle about `axis` in [0, 1) (phi / 2 pi), in the frame of `orthonormal_basis(axis)`.
fn phi01(axis: Vec3, w: Vec3) -> f32 {
    let (t, b) = orthonormal_basis(axis);
    (w.dot(b).atan2(w.dot(t)) / (2.0 * PI)).rem_euclid(1.0)
}

/// Distant light, delta and with a 20 degree angular diameter: (a) P = pi R^2 E 2/(1 + cos
/// theta) (pi R^2 E for the delta); (b) directions uniform in the cone: 1 - cos alpha uniform
/// on [0, 1 - cos theta] and phi uniform; (c) origins uniform on the disc (rho^2 / R^2 and phi
/// uniform), on the sphere's near side ((o - c) . w = -R) and never inside the sphere.
#[test]
fn distant_rays() {
    let d = Vec3::new(-0.5, 0.6, -0.62).normalize();
    let e = Vec3::new(5.0, 4.6, 4.0);
    for half_deg in [0.0f32, 10.0] {
        let half = half_deg.to_radians();
        let scene = scene_with(vec![Light::Distant { direction: d, irradiance: e, half_angle: half }]);
        let sampler = LightSampler::new(&scene);
        let BoundingSphere { center: c, radius: r } = sampler.bounding_sphere();
        let closed = e * (PI * r * r) * (2.0 / (1.0 + half.cos()));
        assert!((sampler.total_power() - closed).abs().max_element() < 1e-4 * closed.max_element());
        let rs = rays(&sampler, N, 1);
        assert_mean_power(&rs, closed, "distant");
        let omc = 1.0 - half.cos();
        for ray in &rs {
            assert!(ray.direction.dot(d) >= half.cos() - 1e-5, "direction outside the cone");
            assert!(((ray.origin - c).dot(ray.direction) + r).abs() < 1e-4 * r, "origin off the near disc");
            assert!((ray.origin - c).length() >= r * (1.0 - 1e-5), "origin inside the bounding sphere");
        }
        if half > 0.0 {
            assert_uniform(rs.iter().map(|x| (1.0 - x.direction.dot(d)) / omc), 20, "distant 1 - cos");
            assert_uniform(rs.iter().map(|x| phi01(d, x.direction)), 16, "distant phi");
        }
        let on_disc = |x: &LightRay| {
            let q = (x.origin - c + x.direction * r) / r;
            (q.length_squared(), phi01(x.direction, q))
        };
        assert_uniform(rs.iter().map(|x| on_disc(x).0), 20, "distant disc rho^2");
        assert_uniform(rs.iter().map(|x| on_disc(x).1), 16, "distant disc phi");
    }
}

/// Point light: (a) P = 4 pi I; (b) directions uniform over the sphere (cos and phi about Z);
/// (c) every ray starts at the light.
#[test]
fn point_rays() {
    let (p, i) = (Vec3::new(1.0, 0.0, 1.0), Vec3::new(50.0, 40.0, 30.0));
    let scene = scene_with(vec![Light::Point { position: p, intensity: i, radius: 0.0, interior: Default::default() }]);
    let rs = rays(&LightSampler::new(&scene), N, 2);
    assert_mean_power(&rs, i * 4.0 * PI, "point");
    assert!(rs.iter().all(|x| x.origin == p));
    assert_uniform(rs.iter().map(|x| 0.5 * (1.0 - x.direction.z)), 20, "point cos");
    assert_uniform(rs.iter().map(|x| phi01(Vec3::Z, x.direction)), 16, "point phi");
}

/// Sphere light (radius 0.3): (a) P = 4 pi I (uniform radiance I / (pi r^2) over 4 pi r^2);
/// (b) about the outward normal the cosine law: cos^2 uniform on [0, 1], phi uniform;
/// (c) origins on the surface, uniform over it (z of the normal uniform in [-1, 1]).
#[test]
fn sphere_rays() {
    let (p, i, radius) = (Vec3::new(0.5, -0.2, 1.5), Vec3::splat(10.0), 0.3);
    let scene = scene_with(vec![Light::Point { position: p, intensity: i, radius, interior: Default::default() }]);
    let rs = rays(&LightSampler::new(&scene), N, 3);
    assert_mean_power(&rs, i * 4.0 * PI, "sphere");
    let normals: Vec<Vec3> = rs.iter().map(|x| (x.origin - p) / radius).collect();
    assert!(normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    assert_uniform(normals.iter().map(|n| 0.5 * (1.0 - n.z)), 20, "sphere surface z");
    assert_uniform(rs.iter().zip(&normals).map(|(x, n)| x.direction.dot(*n).powi(2)), 20, "sphere cos^2");
    assert_uniform(rs.iter().zip(&normals).map(|(x, n)| phi01(*n, x.direction)), 16, "sphere phi");
}

/// Spot (30 degree cone, blend 0.5 as docs/scene-format.md: cos_inner = cos_outer + (1 -
/// cos_outer) blend), and a hard-edged one (blend 0): (a) P = I x 2 pi ((1 - cos_inner) +
/// (cos_inner - cos_outer) / 2), the profile's integral; (b) cos theta about the axis in 30
/// bins over [cos_outer, 1] against the falloff's integral over each bin (4000-step midpoint
/// quadrature, 1e-6 relative), phi uniform; (c) rays start at the light.
#[test]
fn spot_rays() {
    let axis = Vec3::new(0.0, 0.3, -1.0).normalize();
    let cos_outer = 30f32.to_radians().cos();
    for blend in [0.5f32, 0.0] {
        let cos_inner = cos_outer + (1.0 - cos_outer) * blend;
        let s = Spot { position: Vec3::new(0.0, 0.0, 2.0), axis, intensity: Vec3::new(5.0, 4.0, 3.0), radius: 0.0, cos_outer, cos_inner };
        let scene = scene_with(vec![Light::Spot(s)]);
        let rs = rays(&LightSampler::new(&scene), N, 4);
        let closed = s.intensity * 2.0 * PI * ((1.0 - cos_inner) + 0.5 * (cos_inner - cos_outer));
        assert_mean_power(&rs, closed, "spot");
        assert!(rs.iter().all(|x| x.origin == s.position && x.direction.dot(axis) >= cos_outer - 1e-5));
        let bins = 30;
        let width = (1.0 - cos_outer as f64) / bins as f64;
        let mut probs: Vec<f64> = (0..bins)
            .map(|b| {
                let steps = 4000;
                (0..steps).map(|k| falloff_cos(&s, cos_outer as f64 + width * (b as f64 + (k as f64 + 0.5) / steps as f64))).sum::<f64>() / steps as f64
            })
            .collect();
        let total: f64 = probs.iter().sum();
        probs.iter_mut().for_each(|p| *p /= total);
        let chi2 = chi2_of(rs.iter().map(|x| (x.direction.dot(axis) - cos_outer) / (1.0 - cos_outer)), &probs);
        assert!(chi2 < chi_square_quantile_999(bins - 1), "spot blend {blend}: chi-square {chi2}");
        assert_uniform(rs.iter().map(|x| phi01(axis, x.direction)), 16, "spot phi");
    }
}

/// The spot's falloff as a function of cos theta, in f64 for the expected bin probabilities.
fn falloff_cos(s: &Spot, c: f64) -> f64 {
    let (e0, e1) = (s.cos_outer as f64, s.cos_inner as f64);
    if e1 <= e0 {
        return if c > e0 { 1.0 } else { 0.0 };
    }
    let t = ((c - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Rect and disk lights: (a) P = pi L A; (b) the cosine law about the normal (cos^2 uniform)
/// and phi uniform; (c) origins on the light's plane, inside its shape, uniform over it
/// (for the rect each coordinate uniform, for the disk rho^2 uniform).
#[test]
fn area_rays() {
    let normal = Vec3::new(0.0, 0.0, -1.0);
    let rect = AreaLight { center: Vec3::new(0.2, 0.1, 2.0), normal, tangent: Vec3::X, shape: AreaShape::Rect { width: 2.0, height: 0.5 }, radiance: Vec3::new(3.0, 2.0, 1.0) };
    let disk = AreaLight { shape: AreaShape::Disk { radius: 0.7 }, ..rect };
    for (a, seed) in [(rect, 5), (disk, 6)] {
        let scene = scene_with(vec![Light::Area(a)]);
        let rs = rays(&LightSampler::new(&scene), N, seed);
        assert_mean_power(&rs, a.radiance * PI * a.area(), "area");
        assert_uniform(rs.iter().map(|x| x.direction.dot(normal).powi(2)), 20, "area cos^2");
        assert_uniform(rs.iter().map(|x| phi01(normal, x.direction)), 16, "area phi");
        let bitangent = normal.cross(a.tangent);
        for x in &rs {
            assert!((x.origin - a.center).dot(normal).abs() < 1e-5 && x.direction.dot(normal) >= 0.0);
        }
        let local = |x: &LightRay| ((x.origin - a.center).dot(a.tangent), (x.origin - a.center).dot(bitangent));
        match a.shape {
            AreaShape::Rect { width, height } => {
                assert_uniform(rs.iter().map(|x| (local(x).0 / width + 0.5).clamp(0.0, 0.99999)), 20, "rect x");
                assert_uniform(rs.iter().map(|x| (local(x).1 / height + 0.5).clamp(0.0, 0.99999)), 20, "rect y");
            }
            AreaShape::Disk { radius } => {
                assert!(rs.iter().all(|x| (x.origin - a.center).length() <= radius * (1.0 + 1e-5)));
                assert_uniform(rs.iter().map(|x| (x.origin - a.center).length_squared() / (radius * radius)), 20, "disk rho^2");
            }
        }
    }
}

/// A 32 x 16 lat-long dome with a bright sun and a coloured sky, tinted: (a) P = pi R^2 x the
/// dome's fluence (the exact integral of its pixels, `dome_fluence`); (b) the pixel each ray
/// comes from against the map's luminance x the pixel's exact solid angle (the importance
/// `Environment::sample` uses; its row weights are sin(theta) at the row centre, 0.3% from the
/// exact band area at 16 rows, under the test's resolution), 512 bins merged where fewer than
/// 5 rays are expected; (c) origins on the bounding sphere's near disc, never inside it.
#[test]
fn dome_rays() {
    let (w, h) = (32usize, 16usize);
    let sun = Vec3::new(0.3, 0.5, 0.6).normalize();
    let pixels: Vec<Vec3> = (0..w * h)
        .map(|c| {
            let d = LatLongMap::uv_to_direction([((c % w) as f32 + 0.5) / w as f32, 1.0 - ((c / w) as f32 + 0.5) / h as f32]);
            if d.dot(sun) > 0.95 { Vec3::splat(40.0) } else { Vec3::new(0.3, 0.5, 1.0) * (0.5 + d.z.max(0.0)) }
        })
        .collect();
    let env = Environment { color: Vec3::new(1.0, 0.9, 0.8), map: Some(LatLongMap::new(w, h, pixels.clone())) };
    let scene = scene_with(vec![Light::Dome(env.clone())]);
    let sampler = LightSampler::new(&scene);
    let BoundingSphere { center: c, radius: r } = sampler.bounding_sphere();
    let rs = rays(&sampler, N, 7);
    assert_mean_power(&rs, dome_fluence(&env) * PI * r * r, "dome");
    for ray in &rs {
        assert!(((ray.origin - c).dot(ray.direction) + r).abs() < 1e-4 * r && (ray.origin - c).length() >= r * (1.0 - 1e-5));
    }
    let lum = |p: Vec3| 0.2126 * p.x as f64 + 0.7152 * p.y as f64 + 0.0722 * p.z as f64;
    let omega = |row: usize| {
        let s = |k: usize| (0.5 * std::f64::consts::PI - std::f64::consts::PI * k as f64 / h as f64).sin();
        s(row) - s(row + 1)
    };
    let mut probs: Vec<f64> = (0..w * h).map(|i| lum(pixels[i]) * omega(i / w)).collect();
    let total: f64 = probs.iter().sum();
    probs.iter_mut().for_each(|p| *p /= total);
    let mut counts = vec![0u64; w * h];
    for ray in &rs {
        let [u, v] = LatLongMap::direction_to_uv(-ray.direction);
        let (x, row) = (((u * w as f32) as usize).min(w - 1), (((1.0 - v) * h as f32) as usize).min(h - 1));
        counts[row * w + x] += 1;
    }
    let (chi2, dof) = chi_square_pooled(&counts, &probs, 5.0);
    assert!(chi2 < chi_square_quantile_999(dof), "dome: chi-square {chi2} over {dof} dof");
}

/// The default plume glowing with a linear and a blackbody term: (a) P = `Emission::power()`;
/// (b) directions uniform over the sphere; (c) every origin in an emitting cell, and the rays
/// per block of 4^3 cells (the first term's grid) against the blocks' share of the power
/// (chi-square, blocks expecting fewer than 5 rays merged).
#[test]
fn emission_rays() {
    let mut scene = scene_with(Vec::new());
    let m = &scene.medium;
    let linear = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Linear { color: Vec3::new(2.0, 1.0, 0.5) });
    let fire = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Blackbody { temperature: 1500.0, intensity: 1.0, tint: Vec3::ONE });
    for terms in [vec![linear.clone()], vec![linear, fire]] {
        scene.medium.emission = Some(Emission { terms, vpl_count: 64 });
        let em = scene.medium.emission.as_ref().unwrap();
        let sampler = LightSampler::new(&scene);
        let rs = rays(&sampler, N, 8);
        assert_mean_power(&rs, em.power(), "emission");
        assert!(rs.iter().all(|x| x.light == 0));
        assert_uniform(rs.iter().map(|x| 0.5 * (1.0 - x.direction.z)), 20, "emission cos");
        assert_uniform(rs.iter().map(|x| phi01(Vec3::Z, x.direction)), 16, "emission phi");
        // Blocks of the first term's cells (all terms share the grid here).
        let term = &em.terms[0];
        let block = |ijk: IVec3| ijk.div_euclid(IVec3::splat(4));
        let mut expected: std::collections::HashMap<IVec3, f64> = Default::default();
        for t in &em.terms {
            let dv = t.voxel_volume() as f64;
            t.for_each_emitting_cell(|ijk, e| *expected.entry(block(ijk)).or_default() += e.element_sum() as f64 * dv);
        }
        let mut counts: std::collections::HashMap<IVec3, u64> = Default::default();
        for x in &rs {
            let ijk = term.world_to_index.transform_point3(x.origin).floor().as_ivec3();
            assert!(expected.contains_key(&block(ijk)), "a ray from a cell that does not emit");
            *counts.entry(block(ijk)).or_default() += 1;
        }
        let total: f64 = expected.values().sum();
        let blocks: Vec<(u64, f64)> = expected.iter().map(|(b, e)| (counts.get(b).copied().unwrap_or(0), e / total)).collect();
        let (c, p): (Vec<u64>, Vec<f64>) = blocks.into_iter().unzip();
        let (chi2, dof) = chi_square_pooled(&c, &p, 5.0);
        assert!(chi2 < chi_square_quantile_999(dof), "emission blocks: chi-square {chi2} over {dof} dof");
    }
}

/// Every kind at once: each light's tally (its rays' power summed, over all N rays) estimates
/// its own power within 5 standard errors, the lights are drawn in proportion to their power
/// (chi-square), a spot with a radius starts its rays on its sphere, and the same uniforms give
/// the same ray.
#[test]
fn lights_are_chosen_by_power() {
    let spot = Spot { position: Vec3::new(0.0, 0.0, 2.0), axis: -Vec3::Z, intensity: Vec3::splat(30.0), radius: 0.1, cos_outer: 0.8, cos_inner: 0.9 };
    let area = AreaLight { center: Vec3::new(0.0, 0.0, 2.0), normal: -Vec3::Z, tangent: Vec3::X, shape: AreaShape::Disk { radius: 0.5 }, radiance: Vec3::new(4.0, 3.0, 2.0) };
    let mut scene = scene_with(vec![
        Light::Distant { direction: -Vec3::Z, irradiance: Vec3::new(3.0, 2.0, 1.0), half_angle: 0.01 },
        Light::Point { position: Vec3::ONE, intensity: Vec3::splat(20.0), radius: 0.0, interior: Default::default() },
        Light::Spot(spot),
        Light::Area(area),
        Light::Dome(Environment { color: Vec3::new(0.2, 0.3, 0.5), map: None }),
    ]);
    let m = &scene.medium;
    let term = EmissionTerm::new(m.grid.clone(), m.index_to_world, EmissionLaw::Linear { color: Vec3::new(30.0, 10.0, 2.0) });
    scene.medium.emission = Some(Emission { terms: vec![term], vpl_count: 64 });
    let sampler = LightSampler::new(&scene);
    let rs = rays(&sampler, N, 9);
    let kinds = scene.lights.len() + 1;
    let counts: Vec<u64> = (0..kinds)
        .map(|k| {
            let tally: Vec<LightRay> = rs.iter().map(|x| LightRay { power: if x.light == k { x.power } else { Vec3::ZERO }, ..*x }).collect();
            assert_mean_power(&tally, sampler.light_power(k), &format!("light {k}"));
            rs.iter().filter(|x| x.light == k).count() as u64
        })
        .collect();
    let total = sampler.total_power().element_sum() as f64;
    let probs: Vec<f64> = (0..kinds).map(|k| sampler.light_power(k).element_sum() as f64 / total).collect();
    let chi2 = chi_square(&counts, &probs);
    assert!(chi2 < chi_square_quantile_999(kinds - 1), "light choice: chi-square {chi2}");
    // The spot has a radius: its rays leave its sphere along their direction.
    assert!(rs.iter().filter(|x| x.light == 2).all(|x| ((x.origin - spot.position) - x.direction * spot.radius).length() < 1e-5));
    let u = [0.3, 0.1, 0.7, 0.2, 0.9, 0.4];
    assert_eq!(sampler.sample(u), sampler.sample(u));
    assert!(LightSampler::new(&scene_with(Vec::new())).is_empty());
}
