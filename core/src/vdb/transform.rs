//! Grid transforms (`openvdb/math/Maps.h`): every linear map type, read into an index-to-world
//! affine; the writer picks the simplest map that represents the affine exactly.
//!
//! OpenVDB matrices multiply row vectors (`world = index * M`, translation in row 3), so the
//! 16 stored doubles, read in order, are glam's column-major array of the same map.

use glam::{Affine3A, DAffine3, DMat4, DVec3, Vec3};

use super::bytes::{Reader, Writer};
use crate::error::Result;

/// A grid's transform: the map type's name as stored and the index-to-world map.
#[derive(Clone, Debug)]
pub struct GridTransform {
    pub map_type: String,
    pub index_to_world: DAffine3,
}

impl GridTransform {
    pub fn to_affine3a(&self) -> Affine3A {
        let m = self.index_to_world;
        Affine3A::from_cols(
            m.matrix3.x_axis.as_vec3().into(),
            m.matrix3.y_axis.as_vec3().into(),
            m.matrix3.z_axis.as_vec3().into(),
            m.translation.as_vec3().into(),
        )
    }
}

fn vec3d(r: &mut Reader, what: &str) -> Result<DVec3> {
    Ok(DVec3::new(r.f64(what)?, r.f64(what)?, r.f64(what)?))
}

fn check_scale(r: &Reader, s: DVec3, ty: &str) -> Result<()> {
    if !s.is_finite() || s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
        return Err(r.err(format!("{ty} has a zero or non-finite scale {s}")));
    }
    Ok(())
}

pub(crate) fn read_transform(r: &mut Reader) -> Result<GridTransform> {
    let map_type = r.string("transform map type")?;
    let m = match map_type.as_str() {
        "UniformScaleMap" | "ScaleMap" => {
            let scale = vec3d(r, "scale")?;
            r.skip(4 * 24, "scale map derived values")?;
            check_scale(r, scale, &map_type)?;
            DAffine3::from_scale(scale)
        }
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
            let t = vec3d(r, "translation")?;
            let scale = vec3d(r, "scale")?;
            r.skip(4 * 24, "scale map derived values")?;
            check_scale(r, scale, &map_type)?;
            if !t.is_finite() {
                return Err(r.err(format!("{map_type} has a non-finite translation")));
            }
            DAffine3::from_translation(t) * DAffine3::from_scale(scale)
        }
        "TranslationMap" => {
            let t = vec3d(r, "translation")?;
            if !t.is_finite() {
                return Err(r.err("TranslationMap has a non-finite translation"));
            }
            DAffine3::from_translation(t)
        }
        "AffineMap" | "UnitaryMap" => {
            let mut a = [0.0f64; 16];
            for v in &mut a {
                *v = r.f64("matrix")?;
            }
            let m = DMat4::from_cols_array(&a);
            if a.iter().any(|v| !v.is_finite()) {
                return Err(r.err(format!("{map_type} has non-finite entries")));
            }
            // Last column of OpenVDB's matrix (elements 3, 7, 11, 15) must be (0, 0, 0, 1).
            if a[3] != 0.0 || a[7] != 0.0 || a[11] != 0.0 || a[15] != 1.0 {
                return Err(r.err(format!("{map_type} is not affine (projective column {} {} {} {})", a[3], a[7], a[11], a[15])));
            }
            let det = m.determinant();
            if !det.is_finite() || det.abs() <= 1e-300 {
                return Err(r.err(format!("{map_type} is singular (determinant {det})")));
            }
            DAffine3::from_mat4(m)
        }
        "NonlinearFrustumMap" => {
            return Err(r.err("NonlinearFrustumMap (frustum) transforms are not supported; resample the grid to a linear transform"));
        }
        other => {
            return Err(r.err(format!("unknown transform map type `{other}`")));
        }
    };
    Ok(GridTransform { map_type, index_to_world: m })
}

/// Writes the simplest map that holds `m`: UniformScaleMap, ScaleMap, (Uniform)ScaleTranslateMap,
/// TranslationMap, else AffineMap. Returns the map type written.
pub(crate) fn write_transform(w: &mut Writer, m: Affine3A) -> &'static str {
    let m3 = glam::Mat3::from(m.matrix3);
    let t = Vec3::from(m.translation).as_dvec3();
    let diagonal = m3.x_axis.y == 0.0
        && m3.x_axis.z == 0.0
        && m3.y_axis.x == 0.0
        && m3.y_axis.z == 0.0
        && m3.z_axis.x == 0.0
        && m3.z_axis.y == 0.0;
    let scale = DVec3::new(m3.x_axis.x as f64, m3.y_axis.y as f64, m3.z_axis.z as f64);
    if diagonal && scale.x != 0.0 && scale.y != 0.0 && scale.z != 0.0 {
        let uniform = scale.x == scale.y && scale.y == scale.z;
        let translate = t != DVec3::ZERO;
        if uniform && scale == DVec3::ONE && translate {
            w.string("TranslationMap");
            write_vec3d(w, t);
            return "TranslationMap";
        }
        let name = match (uniform, translate) {
            (true, false) => "UniformScaleMap",
            (false, false) => "ScaleMap",
            (true, true) => "UniformScaleTranslateMap",
            (false, true) => "ScaleTranslateMap",
        };
        w.string(name);
        if translate {
            write_vec3d(w, t);
        }
        // ScaleMap's fields: scale, voxel size, inverse scale, inverse scale squared,
        // half inverse scale (openvdb/math/Maps.h, ScaleMap constructor).
        let inv = DVec3::ONE / scale;
        write_vec3d(w, scale);
        write_vec3d(w, scale.abs());
        write_vec3d(w, inv);
        write_vec3d(w, inv * inv);
        write_vec3d(w, inv * 0.5);
        return name;
    }
    write_affine_map(w, &glam::Mat4::from(m).as_dmat4());
    "AffineMap"
}

/// Writes `m` (index to world, column vectors) as an AffineMap in double precision as given:
/// OpenVDB's matrix is row-vector, so its rows are our columns.
pub(crate) fn write_affine_map(w: &mut Writer, m: &DMat4) {
    w.string("AffineMap");
    for v in m.to_cols_array() {
        w.f64(v);
    }
}

fn write_vec3d(w: &mut Writer, v: DVec3) {
    w.f64(v.x);
    w.f64(v.y);
    w.f64(v.z);
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn roundtrip(m: Affine3A) -> (&'static str, Affine3A) {
        let mut w = Writer::default();
        let name = write_transform(&mut w, m);
        let mut r = Reader::new(&w.buf, Path::new("t"));
        let t = read_transform(&mut r).unwrap();
        assert_eq!(t.map_type, name);
        assert_eq!(r.remaining(), 0);
        (name, t.to_affine3a())
    }

    #[test]
    fn picks_the_simplest_map_and_reads_it_back() {
        let cases = [
            (Affine3A::from_scale(Vec3::splat(0.1)), "UniformScaleMap"),
            (Affine3A::from_scale(Vec3::new(0.1, 0.2, 0.3)), "ScaleMap"),
            (Affine3A::from_translation(Vec3::new(1.0, 2.0, 3.0)) * Affine3A::from_scale(Vec3::splat(0.5)), "UniformScaleTranslateMap"),
            (Affine3A::from_translation(Vec3::new(1.0, 2.0, 3.0)) * Affine3A::from_scale(Vec3::new(0.5, 1.0, 2.0)), "ScaleTranslateMap"),
            (Affine3A::from_translation(Vec3::new(1.0, 2.0, 3.0)), "TranslationMap"),
            (Affine3A::from_rotation_z(0.3) * Affine3A::from_scale(Vec3::splat(0.1)), "AffineMap"),
        ];
        for (m, want) in cases {
            let (name, back) = roundtrip(m);
            assert_eq!(name, want);
            assert!(back.abs_diff_eq(m, 1e-7), "{want}: {back:?} vs {m:?}");
        }
    }

    #[test]
    fn refuses_singular_and_projective_maps() {
        let mut w = Writer::default();
        w.string("AffineMap");
        for _ in 0..16 {
            w.f64(0.0);
        }
        assert!(read_transform(&mut Reader::new(&w.buf, Path::new("t"))).is_err());
        let mut w = Writer::default();
        w.string("ScaleMap");
        for _ in 0..15 {
            w.f64(0.0);
        }
        assert!(read_transform(&mut Reader::new(&w.buf, Path::new("t"))).is_err());
        let mut w = Writer::default();
        w.string("NonlinearFrustumMap");
        assert!(read_transform(&mut Reader::new(&w.buf, Path::new("t"))).unwrap_err().to_string().contains("Frustum"));
    }
}
