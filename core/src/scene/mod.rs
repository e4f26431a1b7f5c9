//! The scene model: one medium, its lights, a camera and solver settings. Built from the
//! versioned JSON form (`json.rs`, docs/scene-format.md) or piecewise by hosts.

pub mod camera;
pub mod emission;
pub mod environment;
pub mod json;
pub mod light;

use glam::{Affine3A, Mat4, Vec3};
use std::path::{Path, PathBuf};

pub use camera::Camera;
pub use environment::{Environment, LatLongMap};
pub use json::SceneJson;
pub use light::{AreaLight, AreaShape, Light, SphereInterior, Spot};

use crate::error::{excerpt, Error, Result};
use crate::medium::{procedural, raw, GridLimits, Medium};

/// Largest image side and pixel count accepted (checked before any buffer is allocated).
pub const MAX_IMAGE_SIDE: u32 = 16384;
pub const MAX_IMAGE_PIXELS: u64 = 1 << 26;

#[derive(Clone, Debug)]
pub struct Scene {
    pub medium: Medium,
    pub lights: Vec<Light>,
    pub camera: Camera,
    /// The `solver` block of the JSON: `name` and per-solver settings.
    pub solver: serde_json::Map<String, serde_json::Value>,
}

/// The embedded default scene: the procedural plume under a warm sun and a blue sky.
pub const DEFAULT_SCENE_JSON: &str = r#"{
  "format": 1,
  "medium": {"procedural": "plume", "dims": [64], "density_scale": 12.0,
             "albedo": [0.95, 0.95, 0.95], "g": 0.6},
  "lights": [
    {"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": [5.0, 4.6, 4.0], "angle_deg": 0.53},
    {"type": "dome", "color": [0.12, 0.17, 0.28]}
  ],
  "camera": {"position": [0, -4.6, 0.3], "look_at": [0, 0, 0], "up": [0, 0, 1],
             "fov_deg": 39.6, "width": 256, "height": 256},
  "solver": {"name": "reference", "spp": 64}
}"#;

fn finite3(field: &str, v: [f32; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(Vec3::from(v))
    } else {
        Err(Error::scene(field, format!("must be finite numbers, got {v:?}")))
    }
}

fn non_negative(field: &str, v: json::Rgb) -> Result<Vec3> {
    let a = v.to_array();
    if a.iter().all(|x| x.is_finite() && *x >= 0.0) {
        Ok(Vec3::from(a))
    } else {
        Err(Error::scene(field, format!("must be finite and >= 0, got {a:?}")))
    }
}

impl Scene {
    pub fn default_scene() -> Self {
        Scene::from_json_str(DEFAULT_SCENE_JSON, Path::new(".")).expect("embedded default scene is valid")
    }

    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let base = path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        Scene::from_json_str(&text, &base).map_err(|e| match e {
            Error::Scene { field, message } => Error::Scene { field: format!("{}: {field}", path.display()), message },
            other => other,
        })
    }

    /// Parses and validates scene JSON; relative file paths resolve against `base_dir`.
    pub fn from_json_str(text: &str, base_dir: &Path) -> Result<Self> {
        let de = &mut serde_json::Deserializer::from_str(text);
        // serde's messages quote the input (an unknown 100 MB key, a string where a number
        // belongs): both the field path and the message are cut to an excerpt.
        let parsed: SceneJson = serde_path_to_error::deserialize(&mut *de).map_err(|e| {
            let path = e.path().to_string();
            let path = light_field(text, &path).unwrap_or(path);
            let field = if path == "." { "(root)".to_string() } else { excerpt(&path).into_owned() };
            Error::scene(field, excerpt(&e.into_inner().to_string()).into_owned())
        })?;
        // Text after the object is a mistake (two scenes pasted together, a truncated edit),
        // not something to ignore.
        de.end().map_err(|e| Error::scene("(root)", format!("text after the scene's JSON object: {e}")))?;
        Scene::from_json(parsed, base_dir)
    }

    pub fn from_json(j: SceneJson, base_dir: &Path) -> Result<Self> {
        if j.format != 1 {
            return Err(Error::scene("format", format!("version {} is not supported (this build reads 1)", j.format)));
        }
        let medium = build_medium(&j.medium, base_dir)?;
        let mut lights = Vec::with_capacity(j.lights.len());
        for (i, l) in j.lights.iter().enumerate() {
            lights.push(build_light(l, &format!("lights[{i}]"), base_dir)?);
        }
        let camera = build_camera(&j.camera)?;
        if let Some(name) = j.solver.get("name") {
            if !name.is_string() {
                return Err(Error::scene("solver.name", "must be a string"));
            }
        }
        Ok(Scene { medium, lights, camera, solver: j.solver })
    }

    /// What loading the scene changed, for the host to tell the user (a dome map reduced, bad
    /// pixels zeroed).
    pub fn notes(&self) -> Vec<String> {
        self.lights.iter().filter_map(|l| if let Light::Dome(env) = l { env.map.as_ref() } else { None }).flat_map(|m| m.notes.iter().cloned()).collect()
    }

    pub fn solver_name(&self) -> Option<&str> {
        self.solver.get("name").and_then(|v| v.as_str())
    }

    pub fn environment(&self) -> Option<&Environment> {
        self.lights.iter().find_map(|l| match l {
            Light::Dome(e) => Some(e),
            _ => None,
        })
    }
}

/// Lights are an internally tagged enum, which serde reads through a buffer: an error inside a
/// light is reported at `lights[i]`, without the field. For the colour fields, the one at fault
/// is found by reading each again on its own.
fn light_field(text: &str, path: &str) -> Option<String> {
    let i: usize = path.strip_prefix("lights[")?.strip_suffix(']')?.parse().ok()?;
    let doc: serde_json::Value = serde_json::from_str(text).ok()?;
    let light = doc.get("lights")?.get(i)?.as_object()?;
    ["irradiance", "intensity", "radiance", "color"]
        .into_iter()
        .find(|k| light.get(*k).is_some_and(|v| serde_json::from_value::<json::Rgb>(v.clone()).is_err()))
        .map(|k| format!("{path}.{k}"))
}

pub fn build_camera(c: &json::CameraJson) -> Result<Camera> {
    let position = finite3("camera.position", c.position)?;
    let look_at = finite3("camera.look_at", c.look_at)?;
    let up = finite3("camera.up", c.up)?;
    if (look_at - position).length() < 1e-6 {
        return Err(Error::scene("camera.look_at", "must differ from camera.position"));
    }
    if (look_at - position).normalize().cross(up).length() < 1e-4 {
        return Err(Error::scene("camera.up", "must not be parallel to the viewing direction"));
    }
    if !(c.fov_deg > 0.0 && c.fov_deg < 179.0) {
        return Err(Error::scene("camera.fov_deg", format!("must be in (0, 179), got {}", c.fov_deg)));
    }
    for (name, v) in [("camera.width", c.width), ("camera.height", c.height)] {
        if v == 0 || v > MAX_IMAGE_SIDE {
            return Err(Error::scene(name, format!("must be in 1..={MAX_IMAGE_SIDE}, got {v}")));
        }
    }
    if c.width as u64 * c.height as u64 > MAX_IMAGE_PIXELS {
        return Err(Error::scene(
            "camera.width",
            format!("{}x{} pixels is over the limit of {MAX_IMAGE_PIXELS}", c.width, c.height),
        ));
    }
    Ok(Camera::look_at(position, look_at, up, c.fov_deg, c.width, c.height))
}

pub fn build_light(l: &json::LightJson, field: &str, base_dir: &Path) -> Result<Light> {
    Ok(match l {
        json::LightJson::Distant { direction, irradiance, angle_deg } => {
            let d = unit(&format!("{field}.direction"), *direction)?;
            if !(angle_deg.is_finite() && (0.0..180.0).contains(angle_deg)) {
                return Err(Error::scene(format!("{field}.angle_deg"), format!("must be in [0, 180), got {angle_deg}")));
            }
            Light::Distant {
                direction: d,
                irradiance: non_negative(&format!("{field}.irradiance"), *irradiance)?,
                half_angle: 0.5 * angle_deg.to_radians(),
            }
        }
        json::LightJson::Point { position, intensity, radius, interior } => {
            if !(radius.is_finite() && *radius >= 0.0) {
                return Err(Error::scene(format!("{field}.radius"), format!("must be finite and >= 0, got {radius}")));
            }
            Light::Point {
                position: finite3(&format!("{field}.position"), *position)?,
                intensity: non_negative(&format!("{field}.intensity"), *intensity)?,
                radius: *radius,
                interior: match interior {
                    json::InteriorJson::Dark => light::SphereInterior::Dark,
                    json::InteriorJson::Lit => light::SphereInterior::Lit,
                },
            }
        }
        json::LightJson::Spot { position, direction, intensity, cone_half_angle_deg, blend, radius } => {
            let axis = unit(&format!("{field}.direction"), *direction)?;
            if !(cone_half_angle_deg.is_finite() && *cone_half_angle_deg > 0.0 && *cone_half_angle_deg <= 180.0) {
                return Err(Error::scene(format!("{field}.cone_half_angle_deg"), format!("must be in (0, 180], got {cone_half_angle_deg}")));
            }
            if !(blend.is_finite() && (0.0..=1.0).contains(blend)) {
                return Err(Error::scene(format!("{field}.blend"), format!("must be in [0, 1], got {blend}")));
            }
            if !(radius.is_finite() && *radius >= 0.0) {
                return Err(Error::scene(format!("{field}.radius"), format!("must be finite and >= 0, got {radius}")));
            }
            let cos_outer = cone_half_angle_deg.to_radians().cos();
            Light::Spot(light::Spot {
                position: finite3(&format!("{field}.position"), *position)?,
                axis,
                intensity: non_negative(&format!("{field}.intensity"), *intensity)?,
                radius: *radius,
                cos_outer,
                cos_inner: cos_outer + (1.0 - cos_outer) * blend,
            })
        }
        json::LightJson::Rect { position, normal, tangent, size, radiance } => {
            if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(Error::scene(format!("{field}.size"), format!("must be two sizes > 0, got {size:?}")));
            }
            let shape = light::AreaShape::Rect { width: size[0], height: size[1] };
            area_light(field, *position, *normal, *tangent, shape, *radiance)?
        }
        json::LightJson::Disk { position, normal, radius, radiance } => {
            if !(radius.is_finite() && *radius > 0.0) {
                return Err(Error::scene(format!("{field}.radius"), format!("must be > 0, got {radius}")));
            }
            area_light(field, *position, *normal, None, light::AreaShape::Disk { radius: *radius }, *radiance)?
        }
        json::LightJson::Dome { color, texture, intensity } => {
            if !(intensity.is_finite() && *intensity >= 0.0) {
                return Err(Error::scene(format!("{field}.intensity"), format!("must be finite and >= 0, got {intensity}")));
            }
            let map = match texture {
                Some(t) => {
                    let read = crate::io::exr::read_latlong(&scene_file(&format!("{field}.texture"), t, base_dir)?)?;
                    let mut map = LatLongMap::new(read.width, read.height, read.pixels);
                    map.notes = read.notes;
                    Some(map)
                }
                None => None,
            };
            let colour = match color {
                Some(c) => non_negative(&format!("{field}.color"), *c)?,
                None if map.is_some() => Vec3::ONE,
                None => return Err(Error::scene(field, "a dome needs `color` or `texture`")),
            };
            Light::Dome(Environment { color: colour * *intensity, map })
        }
    })
}

/// A file named by the scene, resolved against `base_dir`. Paths longer than any file system
/// takes (Linux's PATH_MAX, 4096 bytes) are refused here, so the error that names the path
/// cannot echo megabytes of input.
fn scene_file(field: &str, name: &str, base_dir: &Path) -> Result<PathBuf> {
    const MAX_PATH_BYTES: usize = 4096;
    if name.len() > MAX_PATH_BYTES {
        return Err(Error::scene(field, format!("a path of {} bytes is longer than any file system allows: `{}`", name.len(), excerpt(name))));
    }
    Ok(base_dir.join(name))
}

/// A finite, non-zero vector, normalised.
fn unit(field: &str, v: [f32; 3]) -> Result<Vec3> {
    let d = finite3(field, v)?;
    if d.length() < 1e-6 {
        return Err(Error::scene(field, "must not be zero"));
    }
    Ok(d.normalize())
}

fn area_light(field: &str, position: [f32; 3], normal: [f32; 3], tangent: Option<[f32; 3]>, shape: light::AreaShape, radiance: json::Rgb) -> Result<Light> {
    let normal = unit(&format!("{field}.normal"), normal)?;
    let hint = match tangent {
        Some(t) => Some(unit(&format!("{field}.tangent"), t)?),
        None => None,
    };
    Ok(Light::Area(light::AreaLight {
        center: finite3(&format!("{field}.position"), position)?,
        normal,
        tangent: light::tangent_for(normal, hint),
        shape,
        radiance: non_negative(&format!("{field}.radiance"), radiance)?,
    }))
}

fn build_medium(m: &json::MediumJson, base_dir: &Path) -> Result<Medium> {
    let density_scale = non_negative("medium.density_scale", m.density_scale)?;
    let albedo = non_negative("medium.albedo", m.albedo)?;
    if albedo.max_element() > 1.0 {
        return Err(Error::scene("medium.albedo", format!("must be in [0, 1], got {albedo}")));
    }
    if !(m.g.is_finite() && m.g > -1.0 && m.g < 1.0) {
        return Err(Error::scene("medium.g", format!("must be in (-1, 1), got {}", m.g)));
    }
    let object_to_world = match &m.transform {
        None => Affine3A::IDENTITY,
        Some(t) => {
            if t.len() != 16 || t.iter().any(|x| !x.is_finite()) {
                return Err(Error::scene("medium.transform", "must be 16 finite numbers (row-major 4x4)"));
            }
            // Row-major in JSON, column-major in glam.
            let mat = Mat4::from_cols_array(&t[..].try_into().unwrap()).transpose();
            if mat.row(3).abs_diff_eq(glam::Vec4::W, 1e-6) && mat.determinant().abs() > 1e-12 {
                Affine3A::from_mat4(mat)
            } else {
                return Err(Error::scene("medium.transform", "must be an invertible affine matrix (last row 0 0 0 1)"));
            }
        }
    };
    let limits = GridLimits::default();
    let sources = [m.vdb.is_some(), m.procedural.is_some(), m.raw.is_some()].iter().filter(|&&b| b).count();
    if sources != 1 {
        return Err(Error::scene("medium", "needs exactly one of `vdb`, `procedural`, `raw`"));
    }
    if m.max_resolution.is_some() && m.vdb.is_none() {
        return Err(Error::scene("medium.max_resolution", "is for a `vdb` medium (a procedural or raw medium takes its resolution from `dims`)"));
    }
    let (grid, index_to_object) = if let Some(name) = &m.procedural {
        let build = match name.as_str() {
            "plume" => procedural::plume,
            "cumulus" => crate::medium::cumulus::cumulus,
            _ => return Err(Error::scene("medium.procedural", format!("unknown procedural medium `{}` (known: plume, cumulus)", excerpt(name)))),
        };
        let n = match m.dims.as_deref() {
            None => 64,
            Some([n]) if (4..=1024).contains(n) => *n,
            Some(_) => return Err(Error::scene("medium.dims", "for `procedural` must be one number in 4..=1024")),
        };
        build(n, limits)?
    } else if let Some(file) = &m.raw {
        let dims = match m.dims.as_deref() {
            Some(&[x, y, z]) => [x, y, z],
            _ => return Err(Error::scene("medium.dims", "for `raw` must be three voxel counts")),
        };
        let origin = finite3("medium.origin", m.origin.unwrap_or([0.0; 3]))?;
        let voxel = m.voxel_size.unwrap_or(1.0);
        if !(voxel.is_finite() && voxel > 0.0) {
            return Err(Error::scene("medium.voxel_size", format!("must be > 0, got {voxel}")));
        }
        let grid = raw::read_raw_f32(&scene_file("medium.raw", file, base_dir)?, dims, limits)?;
        (grid, Affine3A::from_translation(origin) * Affine3A::from_scale(Vec3::splat(voxel)))
    } else {
        let file = scene_file("medium.vdb", m.vdb.as_ref().unwrap(), base_dir)?;
        match m.max_resolution {
            None => crate::vdb::load_density(&file, m.grid.as_deref(), limits)?,
            Some(n) => filtered_vdb(&file, m, n, limits)?,
        }
    };
    let mut medium = Medium::new(grid, object_to_world * index_to_object, density_scale, albedo, m.g);
    if let Some(e) = &m.emission {
        let vdb = m.vdb.as_ref().map(|f| base_dir.join(f));
        let src = emission::DensitySource { vdb: vdb.as_deref(), grid: &medium.grid, index_to_object, object_to_world };
        medium.emission = Some(emission::build_emission(e, &src, limits)?);
    }
    Ok(medium)
}

/// The `vdb` medium box-filtered to `max_resolution` as it is read (`medium.max_resolution`,
/// vdb/filter.rs). Emission is refused: its grids would be read whole, at full resolution.
fn filtered_vdb(file: &Path, m: &json::MediumJson, max_resolution: u32, limits: GridLimits) -> Result<(crate::medium::DensityGrid, Affine3A)> {
    let max_resolution = crate::vdb::MaxResolution::new(max_resolution).map_err(|why| Error::scene("medium.max_resolution", why))?;
    if m.emission.is_some() {
        return Err(Error::scene(
            "medium.max_resolution",
            "emission is not read box-filtered yet (its grids would be loaded whole at full resolution); leave out max_resolution or the emission",
        ));
    }
    let (grid, xf, _) = crate::vdb::load_density_filtered(file, m.grid.as_deref(), max_resolution, limits)?;
    Ok((grid, xf))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scene_parses() {
        let s = Scene::default_scene();
        assert_eq!(s.lights.len(), 2);
        assert!(s.medium.grid.max_value() > 0.5);
        assert_eq!(s.camera.width, 256);
    }

    fn err_of(json: &str) -> String {
        Scene::from_json_str(json, Path::new(".")).unwrap_err().to_string()
    }

    #[test]
    fn local_lights_parse_and_validate() {
        let with = |lights: &str| DEFAULT_SCENE_JSON.replace(r#"{"type": "dome", "color": [0.12, 0.17, 0.28]}"#, lights);
        let ok = Scene::from_json_str(
            &with(r#"{"type": "spot", "position": [0, 0, 2], "direction": [0, 0, -3], "intensity": 5, "cone_half_angle_deg": 30, "blend": 0.5},
                     {"type": "rect", "position": [1, 0, 0], "normal": [-1, 0, 0], "tangent": [0, 1, 1], "size": [2, 1], "radiance": [1, 2, 3]},
                     {"type": "disk", "position": [0, 1, 0], "normal": [0, -2, 0], "radius": 0.5, "radiance": 4}"#),
            Path::new("."),
        )
        .unwrap();
        match &ok.lights[1] {
            Light::Spot(s) => {
                assert_eq!(s.axis, -Vec3::Z);
                let c = 30f32.to_radians().cos();
                assert!((s.cos_outer - c).abs() < 1e-6 && (s.cos_inner - (c + 0.5 * (1.0 - c))).abs() < 1e-6);
            }
            other => panic!("{other:?}"),
        }
        match &ok.lights[2] {
            Light::Area(a) => {
                // The tangent hint is made perpendicular to the normal.
                assert!(a.tangent.dot(a.normal).abs() < 1e-6 && (a.tangent - Vec3::new(0.0, 1.0, 1.0).normalize()).length() < 1e-6);
                assert_eq!(a.area(), 2.0);
            }
            other => panic!("{other:?}"),
        }
        for (bad, field) in [
            (r#"{"type": "spot", "position": [0, 0, 2], "direction": [0, 0, 0], "intensity": 5, "cone_half_angle_deg": 30}"#, "lights[1].direction"),
            (r#"{"type": "spot", "position": [0, 0, 2], "direction": [0, 0, -1], "intensity": 5, "cone_half_angle_deg": 30, "blend": 2}"#, "lights[1].blend"),
            (r#"{"type": "rect", "position": [0, 0, 2], "normal": [0, 0, -1], "size": [1, -1], "radiance": 1}"#, "lights[1].size"),
            (r#"{"type": "disk", "position": [0, 0, 2], "normal": [0, 0, -1], "radius": 0, "radiance": 1}"#, "lights[1].radius"),
            (r#"{"type": "disk", "position": [0, 0, 2], "normal": [0, 0, -1], "radius": 1, "radiance": -1}"#, "lights[1].radiance"),
        ] {
            let e = err_of(&with(bad));
            assert!(e.contains(field), "{field}: {e}");
        }
    }

    #[test]
    fn bad_scenes_name_the_field() {
        let base = DEFAULT_SCENE_JSON;
        let e = err_of(&base.replace(r#""type": "dome""#, r#""type": "laser""#));
        assert!(e.contains("lights[1]") && e.contains("laser"), "{e}");
        let e = err_of(&base.replace(r#""width": 256"#, r#""width": 1000000"#));
        assert!(e.contains("camera.width"), "{e}");
        let e = err_of(&base.replace(r#""g": 0.6"#, r#""g": 1.5"#));
        assert!(e.contains("medium.g"), "{e}");
        let e = err_of(&base.replace(r#""density_scale": 12.0"#, r#""density_scale": -1"#));
        assert!(e.contains("medium.density_scale"), "{e}");
        let e = err_of(&base.replace(r#""format": 1"#, r#""format": 7"#));
        assert!(e.contains("format"), "{e}");
        let e = err_of(&base.replace(r#""camera": {"#, r#""kamera": {"#));
        assert!(e.contains("kamera"), "{e}");
        let e = err_of(&base.replace(r#""irradiance": [5.0, 4.6, 4.0]"#, r#""irradiance": "bright""#));
        assert!(e.contains("lights[0]"), "{e}");
    }

    /// `medium.max_resolution` (the box-filtered VDB read) is for `vdb` media, in 2..=4096,
    /// and refuses emission (whose grids would be read whole) before reading anything.
    #[test]
    fn max_resolution_is_for_vdb_media_without_emission() {
        let e = err_of(&DEFAULT_SCENE_JSON.replace(r#""dims": [64]"#, r#""dims": [64], "max_resolution": 32"#));
        assert!(e.contains("medium.max_resolution") && e.contains("vdb"), "{e}");
        let vdb = |extra: &str| DEFAULT_SCENE_JSON.replace(r#""procedural": "plume", "dims": [64]"#, &format!(r#""vdb": "missing.vdb"{extra}"#));
        let e = err_of(&vdb(r#", "max_resolution": 1"#));
        assert!(e.contains("medium.max_resolution") && e.contains("2..=4096"), "{e}");
        let e = err_of(&vdb(r#", "max_resolution": 4097"#));
        assert!(e.contains("medium.max_resolution") && e.contains("got 4097"), "{e}");
        let e = err_of(&vdb(r#", "max_resolution": 32, "emission": {"grid": "density"}"#));
        assert!(e.contains("medium.max_resolution") && e.contains("emission"), "{e}");
        let e = err_of(&vdb(r#", "max_resolution": 32"#));
        assert!(e.contains("missing.vdb"), "{e}");
    }

    /// Issue 22: text after the object was ignored; now it is an error naming what follows.
    #[test]
    fn text_after_the_object_is_an_error() {
        let e = err_of(&format!("{DEFAULT_SCENE_JSON} {{\"format\": 1}}"));
        assert!(e.contains("text after the scene's JSON object"), "{e}");
        let e = err_of(&format!("{DEFAULT_SCENE_JSON}garbage"));
        assert!(e.contains("text after"), "{e}");
        // Trailing white space is not text.
        assert!(Scene::from_json_str(&format!("{DEFAULT_SCENE_JSON}\n\t  \n"), Path::new(".")).is_ok());
    }

    /// Issue 22: a 100 MB name was echoed whole. Every message quotes at most
    /// MAX_QUOTE_CHARS characters of input (plus a fixed-size frame: field, reason, the count
    /// of what was left out; 600 bytes is generous for that frame and 10^5 times below the input).
    #[test]
    fn messages_quote_at_most_an_excerpt_of_huge_input() {
        let huge = "x".repeat(10 << 20);
        let cases = [
            DEFAULT_SCENE_JSON.replace(r#""procedural": "plume""#, &format!(r#""procedural": "{huge}""#)),
            DEFAULT_SCENE_JSON.replace(r#""camera": {"#, &format!(r#""{huge}": 1, "camera": {{"#)),
            DEFAULT_SCENE_JSON.replace(r#""type": "dome""#, &format!(r#""type": "{huge}""#)),
            DEFAULT_SCENE_JSON.replace(r#""procedural": "plume", "dims": [64]"#, &format!(r#""vdb": "{huge}.vdb", "grid": "{huge}""#)),
            DEFAULT_SCENE_JSON.replace(r#""color": [0.12, 0.17, 0.28]"#, &format!(r#""texture": "{huge}.exr""#)),
            DEFAULT_SCENE_JSON.replace(r#""width": 256"#, &format!(r#""width": "{huge}""#)),
        ];
        for json in cases {
            let e = err_of(&json);
            assert!(e.len() < 600 && e.contains("xxxxxxxxxx"), "{} bytes: {}", e.len(), &e[..e.len().min(700)]);
        }
    }

    /// Issue 22: "data did not match any variant of untagged enum Rgb" named neither the field
    /// nor the accepted forms.
    #[test]
    fn colour_errors_name_the_field_and_the_accepted_forms() {
        for bad in [r#""bright""#, "[1, 2]", "[1, 2, 3, 4]", "{}", "[1, \"a\", 3]"] {
            let e = err_of(&DEFAULT_SCENE_JSON.replace(r#""irradiance": [5.0, 4.6, 4.0]"#, &format!(r#""irradiance": {bad}"#)));
            assert!(e.contains("lights[0].irradiance") && !e.contains("untagged"), "{bad}: {e}");
            assert!(e.contains("[r, g, b]") || e.contains("f32"), "{bad}: {e}");
        }
        let ok = Scene::from_json_str(&DEFAULT_SCENE_JSON.replace("[0.95, 0.95, 0.95]", "0.5"), Path::new(".")).unwrap();
        assert_eq!(ok.medium.albedo, Vec3::splat(0.5));
    }
}
