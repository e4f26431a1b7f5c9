//! The versioned JSON form of a scene (format 1), as read from disk or from a host. These are
//! plain serde structs; `super::Scene::from_json` validates them and builds the scene model.
//! Documented in docs/scene-format.md — keep the two in step.

use serde::{Deserialize, Serialize};

/// A number or an RGB triple (`10.0` means `[10, 10, 10]`).
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
#[serde(untagged)]
pub enum Rgb {
    Grey(f32),
    Rgb([f32; 3]),
}

/// By hand rather than `#[serde(untagged)]`, whose only message for any mistake is "data did
/// not match any variant of untagged enum Rgb": this one says what was found and what is
/// accepted, and serde_path_to_error adds the field.
impl<'de> Deserialize<'de> for Rgb {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct RgbVisitor;
        const EXPECTED: &str = "a number (grey) or three numbers [r, g, b]";
        impl<'de> serde::de::Visitor<'de> for RgbVisitor {
            type Value = Rgb;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(EXPECTED)
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Rgb, E> {
                Ok(Rgb::Grey(v as f32))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Rgb, E> {
                Ok(Rgb::Grey(v as f32))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Rgb, E> {
                Ok(Rgb::Grey(v as f32))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Rgb, A::Error> {
                let mut out = [0.0f32; 3];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &EXPECTED))?;
                }
                // A fourth element is an error, not silently dropped (counting stops at 4).
                if seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
                    return Err(serde::de::Error::invalid_length(4, &"three numbers [r, g, b] (no alpha)"));
                }
                Ok(Rgb::Rgb(out))
            }
        }
        d.deserialize_any(RgbVisitor)
    }
}

impl Rgb {
    pub fn to_array(self) -> [f32; 3] {
        match self {
            Rgb::Grey(v) => [v; 3],
            Rgb::Rgb(a) => a,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneJson {
    pub format: u32,
    pub medium: MediumJson,
    #[serde(default)]
    pub lights: Vec<LightJson>,
    pub camera: CameraJson,
    /// Solver name and settings; each solver reads the keys it knows (see docs).
    #[serde(default)]
    pub solver: serde_json::Map<String, serde_json::Value>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumJson {
    /// OpenVDB file, relative to the scene file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vdb: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<String>,
    /// For `vdb`: read the grid through a bounded window and box-filter it, as it is read, to
    /// at most this many voxels along its longest side (an integer factor; vdb/filter.rs), so
    /// that a grid larger than memory is never held at full resolution. Absent: loaded whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_resolution: Option<u32>,
    /// Built-in procedural medium: "plume" or "cumulus".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub procedural: Option<String>,
    /// Raw little-endian float32 file, x fastest, with `dims`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw: Option<String>,
    /// Voxel counts for `procedural` (one number, cubic) or `raw` (three numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dims: Option<Vec<u32>>,
    /// For `raw`: world position of the centre of voxel (0,0,0), and the voxel edge length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub voxel_size: Option<f32>,
    #[serde(default = "one")]
    pub density_scale: Rgb,
    #[serde(default = "white")]
    pub albedo: Rgb,
    #[serde(default)]
    pub g: f32,
    /// Row-major object-to-world matrix applied after the grid's own index-to-object map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transform: Option<Vec<f32>>,
    /// Volume emission (fire): see `EmissionJson`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emission: Option<EmissionJson>,
}

/// Emission of the medium, radiance per metre (W/m^3/sr), as Principled Volume's:
/// `strength * color * grid + blackbody_intensity * blackbody_tint * blackbody(temperature *
/// temperature_grid)`. Grids are float grids of the medium's VDB file (or `"density"`, the
/// density grid itself, for any medium). At least one of `grid` and `temperature_grid`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmissionJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<String>,
    #[serde(default = "one")]
    pub color: Rgb,
    #[serde(default = "one_f")]
    pub strength: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_grid: Option<String>,
    /// Kelvin per unit of `temperature_grid` (Principled Volume's Temperature input).
    #[serde(default = "default_temperature")]
    pub temperature: f32,
    #[serde(default = "one_f")]
    pub blackbody_intensity: f32,
    #[serde(default = "white")]
    pub blackbody_tint: Rgb,
    /// Virtual point lights made of the emission by the light translation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vpls: Option<u32>,
}

fn default_temperature() -> f32 {
    1000.0
}

fn one() -> Rgb {
    Rgb::Grey(1.0)
}
fn white() -> Rgb {
    Rgb::Grey(1.0)
}

/// What a sphere lamp gives points inside its sphere (`light::SphereInterior`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InteriorJson {
    #[default]
    Dark,
    Lit,
}

fn is_dark(i: &InteriorJson) -> bool {
    *i == InteriorJson::Dark
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum LightJson {
    /// `direction` is the direction light travels; irradiance in W/m^2 perpendicular to it.
    Distant {
        direction: [f32; 3],
        irradiance: Rgb,
        #[serde(default)]
        angle_deg: f32,
    },
    /// Intensity in W/sr; `radius` > 0 makes a sphere light of the same total power, whose
    /// `interior` is `dark` (the default: UsdLux) or `lit` (Cycles).
    Point {
        position: [f32; 3],
        intensity: Rgb,
        #[serde(default)]
        radius: f32,
        #[serde(default, skip_serializing_if = "is_dark")]
        interior: InteriorJson,
    },
    /// A point light aimed along `direction`: `intensity` (W/sr) on the axis, zero outside the
    /// cone of half-angle `cone_half_angle_deg`, blended over the outer `blend` fraction of
    /// the cone (in the cosine, Blender's spot blend).
    Spot {
        position: [f32; 3],
        direction: [f32; 3],
        intensity: Rgb,
        cone_half_angle_deg: f32,
        #[serde(default)]
        blend: f32,
        #[serde(default)]
        radius: f32,
    },
    /// A one-sided rectangle of uniform `radiance` (W/m^2/sr) emitting towards `normal`;
    /// `size` = [width along `tangent`, height along normal x tangent].
    Rect {
        position: [f32; 3],
        normal: [f32; 3],
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tangent: Option<[f32; 3]>,
        size: [f32; 2],
        radiance: Rgb,
    },
    /// A one-sided disc of uniform `radiance` (W/m^2/sr) emitting towards `normal`.
    Disk {
        position: [f32; 3],
        normal: [f32; 3],
        radius: f32,
        radiance: Rgb,
    },
    /// Uniform `color` radiance (W/m^2/sr), or a lat-long `texture` times `intensity`.
    Dome {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        color: Option<Rgb>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        texture: Option<String>,
        #[serde(default = "one_f")]
        intensity: f32,
    },
}

fn one_f() -> f32 {
    1.0
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraJson {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    #[serde(default = "z_up")]
    pub up: [f32; 3],
    /// Horizontal field of view in degrees.
    #[serde(default = "default_fov")]
    pub fov_deg: f32,
    pub width: u32,
    pub height: u32,
}

fn z_up() -> [f32; 3] {
    [0.0, 0.0, 1.0]
}
fn default_fov() -> f32 {
    39.6
}
