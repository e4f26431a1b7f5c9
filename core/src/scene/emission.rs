//! `medium.emission` of the JSON: validated and turned into `medium::Emission`.

use glam::{Affine3A, Vec3};
use std::path::Path;

use super::json::{EmissionJson, Rgb};
use crate::error::{Error, Result};
use crate::medium::emission::DEFAULT_EMISSION_VPLS;
use crate::medium::{DensityGrid, Emission, EmissionLaw, EmissionTerm, GridLimits};

/// Largest VPL count accepted for `medium.emission.vpls`.
pub const MAX_EMISSION_VPLS: u32 = 1 << 16;

/// Where the medium's own density came from, to find emission grids beside it.
pub struct DensitySource<'a> {
    /// The VDB file (absolute), if the medium is one.
    pub vdb: Option<&'a Path>,
    pub grid: &'a DensityGrid,
    pub index_to_object: Affine3A,
    pub object_to_world: Affine3A,
}

fn non_negative_rgb(field: &str, v: Rgb) -> Result<Vec3> {
    let a = v.to_array();
    if a.iter().all(|x| x.is_finite() && *x >= 0.0) {
        Ok(Vec3::from(a))
    } else {
        Err(Error::scene(field, format!("must be finite and >= 0, got {a:?}")))
    }
}

fn non_negative(field: &str, v: f32) -> Result<f32> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(Error::scene(field, format!("must be finite and >= 0, got {v}")))
    }
}

/// Loads one emission grid: `density` (the medium's own density grid, for any medium) or a
/// float grid of the medium's VDB file. Non-finite values are an error and negative values are
/// clamped to zero by the grid builder (Principled Volume reads max(value, 0) too).
fn load_grid(field: &str, name: &str, src: &DensitySource, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    match src.vdb {
        Some(path) => {
            let (grid, index_to_object) = crate::vdb::load_density(path, Some(name), limits).map_err(|e| Error::scene(field, e.to_string()))?;
            Ok((grid, src.object_to_world * index_to_object))
        }
        None if name == "density" => Ok((src.grid.clone(), src.object_to_world * src.index_to_object)),
        None => Err(Error::scene(field, format!("grid `{}`: only a `vdb` medium has other grids (`density` works for every medium)", crate::error::excerpt(name)))),
    }
}

pub fn build_emission(j: &EmissionJson, src: &DensitySource, limits: GridLimits) -> Result<Emission> {
    let color = non_negative_rgb("medium.emission.color", j.color)? * non_negative("medium.emission.strength", j.strength)?;
    let temperature = non_negative("medium.emission.temperature", j.temperature)?;
    let intensity = non_negative("medium.emission.blackbody_intensity", j.blackbody_intensity)?;
    let tint = non_negative_rgb("medium.emission.blackbody_tint", j.blackbody_tint)?;
    let vpl_count = j.vpls.unwrap_or(DEFAULT_EMISSION_VPLS);
    if !(1..=MAX_EMISSION_VPLS).contains(&vpl_count) {
        return Err(Error::scene("medium.emission.vpls", format!("must be in 1..={MAX_EMISSION_VPLS}, got {vpl_count}")));
    }
    if j.grid.is_none() && j.temperature_grid.is_none() {
        return Err(Error::scene("medium.emission", "needs `grid` (emission strength) or `temperature_grid` (blackbody), or both"));
    }
    let mut terms = Vec::new();
    if let Some(name) = &j.grid {
        let (grid, to_world) = load_grid("medium.emission.grid", name, src, limits)?;
        terms.push(EmissionTerm::new(grid, to_world, EmissionLaw::Linear { color }));
    }
    if let Some(name) = &j.temperature_grid {
        let (grid, to_world) = load_grid("medium.emission.temperature_grid", name, src, limits)?;
        terms.push(EmissionTerm::new(grid, to_world, EmissionLaw::Blackbody { temperature, intensity, tint }));
    }
    Ok(Emission { terms, vpl_count })
}

#[cfg(test)]
mod tests {
    use crate::scene::{Scene, DEFAULT_SCENE_JSON};
    use glam::Vec3;
    use std::path::Path;

    fn with_emission(block: &str) -> crate::error::Result<Scene> {
        let json = DEFAULT_SCENE_JSON.replace(r#""g": 0.6}"#, &format!(r#""g": 0.6, "emission": {block}}}"#));
        Scene::from_json_str(&json, Path::new("."))
    }

    #[test]
    fn emission_parses_and_validates() {
        let s = with_emission(r#"{"grid": "density", "color": [1, 0.5, 0.25], "strength": 2, "temperature_grid": "density", "temperature": 1500, "vpls": 32}"#).unwrap();
        let e = s.medium.emission.as_ref().unwrap();
        assert_eq!((e.terms.len(), e.vpl_count), (2, 32));
        // Where the plume has density 1 the linear term gives strength * color.
        let lin = crate::medium::EmissionLaw::Linear { color: Vec3::new(2.0, 1.0, 0.5) };
        assert_eq!(e.terms[0].law, lin);
        assert!(e.power().x > 0.0);
        for (block, field) in [
            (r#"{"grid": "density", "strength": -1}"#, "medium.emission.strength"),
            (r#"{"grid": "density", "color": [1, "x", 0]}"#, "medium.emission"),
            (r#"{"strength": 2}"#, "medium.emission"),
            (r#"{"grid": "flame"}"#, "medium.emission.grid"),
            (r#"{"temperature_grid": "density", "temperature": -5}"#, "medium.emission.temperature"),
            (r#"{"grid": "density", "vpls": 0}"#, "medium.emission.vpls"),
            (r#"{"grid": "density", "glow": 1}"#, "glow"),
        ] {
            let e = with_emission(block).unwrap_err().to_string();
            assert!(e.contains(field), "{block}: {e}");
        }
    }

    /// From a VDB: a named float grid of the same file, and clear errors for a missing grid or a
    /// vector grid.
    #[test]
    fn emission_grids_come_from_the_vdb() {
        // shared/ sits beside the repository, as for the VDB reader's tests.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures/vdb");
        let scene = |emission: &str| {
            let json = format!(
                r#"{{"format": 1, "medium": {{"vdb": "vec3_and_density_blosc.vdb", "emission": {emission}}},
                    "camera": {{"position": [0, -4, 0], "look_at": [0, 0, 0], "width": 4, "height": 4}}}}"#
            );
            Scene::from_json_str(&json, &dir)
        };
        let s = scene(r#"{"grid": "density", "strength": 3}"#).unwrap();
        let (sum, _) = s.medium.grid.sum_and_count_nonzero();
        let dv = s.medium.voxel_size_world().x.powi(3) as f64;
        let expected = (sum * dv * 3.0 * 4.0 * std::f64::consts::PI) as f32;
        let p = s.medium.emission.as_ref().unwrap().power().x;
        assert!((p - expected).abs() < 1e-4 * expected, "{p} vs {expected}");
        let e = scene(r#"{"grid": "flame"}"#).unwrap_err().to_string();
        assert!(e.contains("medium.emission.grid") && e.contains("flame"), "{e}");
        let e = scene(r#"{"temperature_grid": "velocity"}"#).unwrap_err().to_string();
        assert!(e.contains("medium.emission.temperature_grid") && e.contains("not float"), "{e}");
    }
}
