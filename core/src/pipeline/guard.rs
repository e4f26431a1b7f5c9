//! What every solve checks before it starts and after it ends (issue 22, "work that always
//! ends" and "no NaN/Inf out with status OK"):
//! - before: the medium is one that float32 tracking can step through (finite maps, voxels the
//!   float grid resolves where the medium sits, an optical depth per voxel tracking can step)
//!   and every light's radiance is a finite number with headroom for the products a solver
//!   forms with it. Such media used to loop for ever (a step of 1e-38 m never advances t) and
//!   such lights came back as NaN with status OK.
//! - after: the scattering grid or image is finite; if not, the error names the scene value
//!   most likely to blame rather than handing NaN to the host.

use glam::Vec3;

use crate::error::{Error, Result};
use crate::medium::Medium;
use crate::scene::{Light, Scene};

/// Largest optical depth of one voxel (density x scale x voxel edge) a solve accepts.
/// exp(-1e4) is far below the smallest float, so such a voxel is as opaque as one can be;
/// and tracking takes about this many null-collision steps to cross one voxel of the
/// trilinear ramp around it (1e4 steps ~ 0.3 ms, bounded; 1e8 on a 2 m ball was 6e6 per voxel
/// and never finished).
pub const MAX_OPTICAL_DEPTH_PER_VOXEL: f32 = 1e4;

/// The medium's distance from the origin in voxels may be at most this (2^24: float32 resolves
/// 1/2^24 of a position, so farther out its voxels are no longer distinct positions and the
/// tracking step rounds to zero; 3e38 m or a 1e-20 m voxel at 1 m both fail it).
pub const MAX_REACH_IN_VOXELS: f32 = (1u32 << 24) as f32;

/// Largest radiance, intensity or irradiance a light may have. Solvers multiply it by phase
/// values, coefficients and geometry terms (up to ~1e8 together) in float32 (max 3.4e38).
pub const MAX_LIGHT_VALUE: f32 = 1e30;

/// Refuses scenes no solver can finish or keep finite; the message names the field.
pub fn check_scene(scene: &Scene) -> Result<()> {
    check_medium(&scene.medium)?;
    for (i, light) in scene.lights.iter().enumerate() {
        check_light(i, light)?;
    }
    Ok(())
}

/// See `check_scene`: the medium's maps, reach and optical depth per voxel.
pub fn check_medium(m: &Medium) -> Result<()> {
    let finite = |a: &glam::Affine3A| a.to_cols_array().iter().all(|v| v.is_finite());
    if !finite(&m.index_to_world) || !finite(&m.world_to_index) {
        return Err(Error::scene("medium", "its voxel-to-world map is not invertible in float32 (a voxel size or scale near 0 or beyond 1e38)"));
    }
    if m.grid.is_empty() {
        return Ok(());
    }
    let voxel = m.voxel_size_world();
    let (lo, hi) = m.world_bounds();
    let reach = lo.abs().max(hi.abs()).max_element();
    if !(voxel.min_element() > 0.0 && reach.is_finite() && reach / voxel.min_element() <= MAX_REACH_IN_VOXELS) {
        return Err(Error::scene(
            "medium",
            format!(
                "voxels of {:e} m at up to {reach:e} m from the origin are beyond float32 precision (at most {MAX_REACH_IN_VOXELS:e} voxels from the origin): move the medium nearer the origin or use larger voxels",
                voxel.min_element()
            ),
        ));
    }
    let sigma_max = m.density_scale.max_element() * m.grid.max_value();
    let depth = sigma_max * voxel.max_element();
    // NaN and infinity fail too (a density of 3e38 times a scale of 10).
    if depth.is_nan() || depth > MAX_OPTICAL_DEPTH_PER_VOXEL {
        return Err(Error::scene(
            "medium.density_scale",
            format!(
                "largest extinction {sigma_max:e}/m (density {:e} x scale {:e}) over voxels of {:e} m is an optical depth of {depth:e} per voxel, beyond the {MAX_OPTICAL_DEPTH_PER_VOXEL:e} tracking can step through (and already opaque): lower the density scale",
                m.grid.max_value(),
                m.density_scale.max_element(),
                voxel.max_element()
            ),
        ));
    }
    Ok(())
}

fn check_light(i: usize, light: &Light) -> Result<()> {
    let within = |field: &str, what: &str, v: Vec3| -> Result<()> {
        if v.is_finite() && v.max_element() <= MAX_LIGHT_VALUE {
            Ok(())
        } else {
            Err(Error::scene(format!("lights[{i}].{field}"), format!("{what} {:e} is beyond {MAX_LIGHT_VALUE:e}, too large for float32 arithmetic", v.max_element())))
        }
    };
    let sphere = |intensity: Vec3, radius: f32| -> Result<()> {
        within("intensity", "intensity", intensity)?;
        if radius > 0.0 {
            let radiance = intensity / (std::f32::consts::PI * radius * radius);
            if !(radiance.is_finite() && radiance.max_element() <= MAX_LIGHT_VALUE) {
                return Err(Error::scene(
                    format!("lights[{i}].radius"),
                    format!("a sphere of radius {radius:e} m has radiance I / (pi r^2) = {:e}, beyond float32 arithmetic: use radius 0 for a point light", radiance.max_element()),
                ));
            }
        }
        Ok(())
    };
    match light {
        Light::Distant { irradiance, half_angle, .. } => {
            within("irradiance", "irradiance", *irradiance)?;
            if *half_angle > 0.0 {
                within("angle_deg", "the sun disc's radiance E / (pi sin^2)", *irradiance / (std::f32::consts::PI * half_angle.sin().powi(2)))?;
            }
            Ok(())
        }
        Light::Point { intensity, radius, .. } => sphere(*intensity, *radius),
        Light::Spot(s) => sphere(s.intensity, s.radius),
        Light::Area(a) => within("radiance", "radiance x area", a.radiance * a.area().max(1.0)),
        Light::Dome(env) => within("color", "dome colour x its map's brightest texel", env.color * map_max(env)),
    }
}

/// The brightest texel of a dome's map (1 without a map).
fn map_max(env: &crate::scene::Environment) -> Vec3 {
    env.map.as_ref().map_or(Vec3::ONE, |m| m.pixels.iter().fold(Vec3::ZERO, |a, &p| a.max(p)))
}

/// Refuses a non-finite result (`what`: "scattering grid", "image"), naming the scene value
/// most likely to blame: the largest light or the densest medium.
pub fn check_finite(scene: &Scene, what: &str, values: impl Iterator<Item = Vec3>) -> Result<()> {
    let (mut bad, mut total) = (0u64, 0u64);
    for v in values {
        total += 1;
        bad += u64::from(!v.is_finite());
    }
    if bad == 0 {
        return Ok(());
    }
    Err(Error::scene(
        "(result)",
        format!("the {what} has {bad} non-finite values of {total}: float32 overflowed; {}", suspect(scene)),
    ))
}

/// The scene's largest magnitude, for `check_finite`'s message.
fn suspect(scene: &Scene) -> String {
    let m = &scene.medium;
    let mut worst = (m.density_scale.max_element() * m.grid.max_value(), "the medium's largest extinction (density x density_scale)".to_string());
    for (i, l) in scene.lights.iter().enumerate() {
        let v = match l {
            Light::Distant { irradiance, .. } => irradiance.max_element(),
            Light::Point { intensity, .. } => intensity.max_element(),
            Light::Spot(s) => s.intensity.max_element(),
            Light::Area(a) => a.radiance.max_element(),
            Light::Dome(e) => (e.color * map_max(e)).max_element(),
        };
        if v.is_nan() || v > worst.0 {
            worst = (v, format!("lights[{i}]"));
        }
    }
    format!("the largest value in the scene is {} ({:e}); lower it", worst.1, worst.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// The default scene passes; the hostile values are refused naming their field.
    #[test]
    fn hostile_values_are_refused_naming_the_field() {
        let ok = Scene::default_scene();
        check_scene(&ok).unwrap();
        let mut s = Scene::default_scene();
        s.medium.density_scale = Vec3::splat(1e8); // 64^3 plume over 2 m: ~4e6 per voxel
        assert!(check_scene(&s).unwrap_err().to_string().contains("density_scale"));
        let mut s = Scene::default_scene();
        s.medium = Medium::new(s.medium.grid.clone(), glam::Affine3A::from_scale(Vec3::splat(1e-45)), Vec3::ONE, Vec3::ONE, 0.0);
        assert!(check_scene(&s).unwrap_err().to_string().contains("not invertible"));
        let mut s = Scene::default_scene();
        s.lights = vec![Light::Point { position: Vec3::Z * 3.0, intensity: Vec3::ONE, radius: 1e-30, interior: Default::default() }];
        assert!(check_scene(&s).unwrap_err().to_string().contains("lights[0].radius"));
        let e = check_finite(&ok, "scattering grid", [Vec3::ONE, Vec3::NAN].into_iter()).unwrap_err().to_string();
        assert!(e.contains("1 non-finite values of 2"), "{e}");
        check_finite(&ok, "image", [Vec3::ONE].into_iter()).unwrap();
    }
}
