//! `VsScene`: a scene loaded from JSON or built piecewise, and the calls that solve or render
//! it. The state is an `Arc<Scene>`: a solve works on a snapshot, so the host may keep editing
//! the scene (or destroy it) while a solve runs on another thread.

use std::ffi::{c_char, c_void};
use std::path::Path;
use std::sync::Arc;

use glam::{Affine3A, IVec3, Mat4, Vec3, Vec4};
use volscatter_core::medium::{DensityGrid, GridLimits};
use volscatter_core::scene::json::{CameraJson, LightJson, Rgb};
use volscatter_core::scene::{self, Camera};
use volscatter_core::compositor::CompositeOptions;
use volscatter_core::pipeline;
use volscatter_core::solvers::registry;
use volscatter_core::{Medium, Scene};

use super::guard::{self, clear_out, finite_arg, floats_arg, in_slice, input_file_arg, on_handle, opt_str_arg, path_arg, str_arg, write_out};
use super::handle::{lock, Handle, Registry};
use super::image::{ImageState, IMAGES};
use super::progress::{CProgress, VsProgressCallback};
use super::result::{ResultState, VsResult, RESULTS};
use super::status::{FfiError, FfiResult, VsStatus};
use super::version::{VS_DEVICE_AUTO, VS_DEVICE_CPU, VS_DEVICE_GPU};
use volscatter_gpu::DeviceChoice;
use super::VsImage;

/// Opaque scene handle. Create with `vs_scene_new`, destroy with `vs_scene_destroy`.
pub struct VsScene {
    _private: [u8; 0],
}

pub(crate) struct SceneState {
    pub(crate) scene: Arc<Scene>,
    has_medium: bool,
    has_camera: bool,
    /// Where GPU-capable stages run (`vs_scene_set_device`); the CPU unless the host asks.
    pub(crate) device: DeviceChoice,
}

pub(crate) static SCENES: Registry<SceneState, VsScene> = Registry::new("VsScene");

/// Largest scene JSON file read by `vs_scene_load_file`.
const MAX_SCENE_FILE_BYTES: u64 = 64 << 20;

/// Largest voxel count per axis of a caller's dense buffer (keeps index arithmetic in i32).
const MAX_DENSE_SIDE: u32 = 1 << 16;

impl SceneState {
    fn empty() -> Self {
        let medium = Medium::new(DensityGrid::empty(), Affine3A::IDENTITY, Vec3::ONE, Vec3::ONE, 0.0);
        let camera = Camera::look_at(Vec3::new(0.0, -6.0, 0.0), Vec3::ZERO, Vec3::Z, 39.6, 256, 256);
        SceneState {
            scene: Arc::new(Scene { medium, lights: Vec::new(), camera, solver: Default::default() }),
            has_medium: false,
            has_camera: false,
            device: DeviceChoice::Cpu,
        }
    }
    /// A whole new scene (loaded JSON or the default); the host's device choice stays.
    fn replace_scene(&mut self, scene: Scene) {
        *self = SceneState { scene: Arc::new(scene), has_medium: true, has_camera: true, device: self.device };
    }
    fn edit(&mut self) -> &mut Scene {
        Arc::make_mut(&mut self.scene)
    }
    /// A snapshot of a complete scene.
    pub(crate) fn snapshot(&self) -> FfiResult<Arc<Scene>> {
        if !self.has_medium {
            return Err(FfiError::scene("the scene has no medium: load a scene or call vs_scene_set_medium_vdb / vs_scene_set_medium_dense"));
        }
        if !self.has_camera {
            return Err(FfiError::scene("the scene has no camera: load a scene or call vs_scene_set_camera"));
        }
        Ok(self.scene.clone())
    }
}

fn with_scene(scene: *mut VsScene, body: impl FnOnce(&Arc<Handle<SceneState>>) -> FfiResult) -> VsStatus {
    on_handle(&SCENES, scene, body)
}

fn edit_scene(scene: *mut VsScene, body: impl FnOnce(&mut SceneState) -> FfiResult) -> VsStatus {
    with_scene(scene, |h| body(&mut lock(&h.state)))
}

/// 16 floats, row-major, an invertible affine map (last row 0 0 0 1).
unsafe fn affine_arg(p: *const f32, what: &str) -> FfiResult<Affine3A> {
    let m: [f32; 16] = floats_arg(p, what)?;
    let mat = Mat4::from_cols_array(&m).transpose();
    if !mat.row(3).abs_diff_eq(Vec4::W, 1e-6) {
        return Err(FfiError::invalid(format!("{what}: last row must be 0 0 0 1 (row-major affine matrix), got {:?}", mat.row(3).to_array())));
    }
    let det = mat.determinant();
    if !(det.is_finite() && det.abs() > 1e-12) {
        return Err(FfiError::invalid(format!("{what}: matrix is not invertible (determinant {det})")));
    }
    Ok(Affine3A::from_mat4(mat))
}

fn rgb(v: [f32; 3]) -> Rgb {
    Rgb::Rgb(v)
}

// ---- lifetime -----------------------------------------------------------------------------

/// Creates an empty scene (no medium, no lights, no camera, default solver) in `*out`.
/// `*out` is set to NULL on failure. Destroy it with `vs_scene_destroy`.
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_new(out: *mut *mut VsScene) -> VsStatus {
    guard::call(|| {
        clear_out(out, "out")?;
        let h = SCENES.insert(SceneState::empty())?;
        write_out(out, h, "out")
    })
}

/// Destroys a scene. NULL is accepted and ignored. Destroying a handle twice, or a handle that
/// is not a live scene, returns `VS_STATUS_INVALID_HANDLE` and does nothing else. Results and
/// images made from the scene stay valid. A solve running on another thread finishes normally.
///
/// Thread safety: may be called from any thread; the handle must not be used afterwards.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_destroy(scene: *mut VsScene) -> VsStatus {
    guard::call(|| if scene.is_null() { Ok(()) } else { SCENES.remove(scene) })
}

/// The message of the last call on this scene that failed, or "" if the last call succeeded.
/// The string belongs to the scene and stays valid until the next call on it (from any thread)
/// or its destruction; copy it to keep it. For a NULL or dead handle, a static description.
///
/// Thread safety: meaningful only when no other thread calls functions on this scene meanwhile.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_last_error(scene: *const VsScene) -> *const c_char {
    guard::value(VsStatus::Internal.description().as_ptr().cast(), || match SCENES.get(scene) {
        Ok(h) => h.error.as_ptr(),
        Err(e) => e.status.description().as_ptr().cast(),
    })
}

// ---- whole scenes -------------------------------------------------------------------------

/// Replaces the scene with one parsed from JSON text (scene format 1, docs/scene-format.md).
/// Relative file paths in it resolve against `base_dir` (NULL: the current directory).
/// On failure the scene is unchanged and the message names the offending field.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_load_json(scene: *mut VsScene, json: *const c_char, base_dir: *const c_char) -> VsStatus {
    with_scene(scene, |h| {
        let text = str_arg(json, "json")?;
        let base = if base_dir.is_null() { Path::new(".").to_path_buf() } else { path_arg(base_dir, "base_dir")? };
        let parsed = Scene::from_json_str(text, &base)?;
        lock(&h.state).replace_scene(parsed);
        Ok(())
    })
}

/// Replaces the scene with the JSON scene file at `path` (relative paths inside it resolve
/// against the file's directory). On failure the scene is unchanged.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_load_file(scene: *mut VsScene, path: *const c_char) -> VsStatus {
    with_scene(scene, |h| {
        let path = input_file_arg(path, "path", MAX_SCENE_FILE_BYTES)?;
        let parsed = Scene::load(&path)?;
        lock(&h.state).replace_scene(parsed);
        Ok(())
    })
}

/// Replaces the scene with the built-in default scene (a procedural plume under a sun and a
/// blue sky, 256x256 camera, reference solver).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_load_default(scene: *mut VsScene) -> VsStatus {
    with_scene(scene, |h| {
        lock(&h.state).replace_scene(Scene::default_scene());
        Ok(())
    })
}

// ---- medium -------------------------------------------------------------------------------

/// Sets the medium's density from the float grid `grid_name` (NULL: the first float grid) of
/// the OpenVDB file at `path`, placed by the file's transform followed by `object_to_world`
/// (16 floats, row-major 4x4 affine; NULL: identity). Keeps the material (see
/// `vs_scene_set_material`). On failure the scene is unchanged.
///
/// Thread safety: any thread; calls on one scene are serialised (the file is read before the
/// scene is locked).
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_medium_vdb(
    scene: *mut VsScene,
    path: *const c_char,
    grid_name: *const c_char,
    object_to_world: *const f32,
) -> VsStatus {
    with_scene(scene, |h| {
        let path = input_file_arg(path, "path", GridLimits::default().max_bytes)?;
        let grid_name = opt_str_arg(grid_name, "grid_name")?;
        let o2w = if object_to_world.is_null() { Affine3A::IDENTITY } else { affine_arg(object_to_world, "object_to_world")? };
        let (grid, index_to_object) = volscatter_core::vdb::load_density(&path, grid_name, GridLimits::default())?;
        let mut st = lock(&h.state);
        let m = &st.scene.medium;
        let medium = Medium::new(grid, o2w * index_to_object, m.density_scale, m.albedo, m.g);
        st.edit().medium = medium;
        st.has_medium = true;
        Ok(())
    })
}

/// `vs_scene_lpm_estimate`'s answer: how large a VDB medium is and what `lpm` will hold for
/// it, from the file's topology alone (no voxel is decoded). Voxel counts are of the leaves'
/// index box (which can be wider than the active voxels'); bytes count 4 a voxel for the
/// medium. All 0 when the grid has no voxel.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct VsLpmEstimate {
    /// Voxels of the grid read whole, along x, y, z.
    pub voxels: [u64; 3],
    /// Bytes of those voxels dense (4 a voxel).
    pub dense_bytes: u64,
    /// Cells of the medium as it will be held (`max_resolution` applied), and their bytes.
    pub medium_dims: [u64; 3],
    pub medium_bytes: u64,
    /// Cells of lpm's propagation grid.
    pub grid_dims: [u64; 3],
    /// lpm in memory: per-cell arrays and sweep buffers (0: `memory_budget` below one layer).
    pub in_memory_bytes: u64,
    /// lpm out of core: the largest slab under `memory_budget` (0: below one layer).
    pub out_of_core_bytes: u64,
    /// lpm out of core: its scratch files on disk.
    pub scratch_bytes: u64,
}

/// Estimates, without reading any voxel, the medium the float grid `grid_name` (NULL: `density`,
/// else the first float grid) of the OpenVDB file at `path` will be, placed by the file's
/// transform and `object_to_world` (16 floats, row-major; NULL: identity), read box-filtered
/// to `max_resolution` cells a side (0: whole; else 2..=4096, like `medium.max_resolution`),
/// and the memory `lpm` with `settings_json` (an object of lpm settings as in a scene's
/// `solver` block; NULL or "": the defaults) will use over it (core `lpm::estimate`: the
/// formulas the solver plans with; the medium, its mip and the output grid are not in the lpm
/// figures). The scene is not changed; errors (bad path, not a VDB, bad settings) are
/// recorded on it for `vs_scene_last_error`, and `*out` is zeroed.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_lpm_estimate(
    scene: *mut VsScene,
    path: *const c_char,
    grid_name: *const c_char,
    object_to_world: *const f32,
    max_resolution: u32,
    settings_json: *const c_char,
    out: *mut VsLpmEstimate,
) -> VsStatus {
    with_scene(scene, |_| {
        if out.is_null() {
            return Err(FfiError::null("out"));
        }
        out.write_unaligned(VsLpmEstimate::default());
        let path = path_arg(path, "path")?;
        let grid_name = opt_str_arg(grid_name, "grid_name")?;
        let o2w = if object_to_world.is_null() { Affine3A::IDENTITY } else { affine_arg(object_to_world, "object_to_world")? };
        let max_resolution = match max_resolution {
            0 => None,
            n => Some(volscatter_core::vdb::MaxResolution::new(n).map_err(|why| FfiError::invalid(format!("max_resolution (0: whole) {why}")))?),
        };
        let settings = lpm_settings_arg(settings_json)?;
        let file = volscatter_core::vdb::VdbFile::open(&path, u64::MAX)?;
        let i = file.find_density_grid(grid_name)?;
        let Some(size) = file.medium_size(i, max_resolution)? else {
            return Ok(());
        };
        let xf = o2w * size.index_to_object;
        let (lo, hi) = volscatter_core::medium::optics::world_box(&xf, size.index_bounds.0, size.index_bounds.1);
        let est = volscatter_core::solvers::lpm::estimate::memory(lo, hi, &settings)?;
        let voxels = (size.fine_box.1 - size.fine_box.0).as_u64vec3().to_array();
        let medium_dims = size.dims.as_u64vec3().to_array();
        // Saturating: a hostile file's leaf box may span the whole i32 index range.
        let bytes = |d: [u64; 3]| d.iter().fold(4u64, |a, &n| a.saturating_mul(n));
        out.write_unaligned(VsLpmEstimate {
            voxels,
            dense_bytes: bytes(voxels),
            medium_dims,
            medium_bytes: bytes(medium_dims),
            grid_dims: est.grid_dims.map(|d| d as u64),
            in_memory_bytes: est.in_memory_bytes,
            out_of_core_bytes: est.out_of_core_bytes,
            scratch_bytes: est.scratch_bytes,
        });
        Ok(())
    })
}

/// lpm settings from a JSON object (NULL or empty: the defaults), checked like a scene's.
unsafe fn lpm_settings_arg(p: *const c_char) -> FfiResult<volscatter_core::solvers::lpm::LpmSettings> {
    let text = opt_str_arg(p, "settings_json")?.unwrap_or("").trim();
    if text.is_empty() {
        return Ok(Default::default());
    }
    let value: serde_json::Value = serde_json::from_str(text).map_err(|e| FfiError::invalid(format!("settings_json: {e}")))?;
    let serde_json::Value::Object(map) = value else {
        return Err(FfiError::invalid("settings_json must be a JSON object of lpm settings"));
    };
    Ok(volscatter_core::solvers::parse_settings(&map)?)
}

/// Sets the medium's density from the caller's dense buffer: `len` floats, x fastest then y
/// then z, `len == nx * ny * nz`, each finite (negative values are clamped to zero). Voxel
/// (i, j, k) sits at index coordinates (i, j, k), placed in the world by `index_to_world`
/// (16 floats, row-major 4x4 affine, required). The data is copied; the buffer may be freed
/// when the call returns. Keeps the material. On failure the scene is unchanged.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_medium_dense(
    scene: *mut VsScene,
    density: *const f32,
    len: usize,
    nx: u32,
    ny: u32,
    nz: u32,
    index_to_world: *const f32,
) -> VsStatus {
    with_scene(scene, |h| {
        let dims = [nx, ny, nz];
        if dims.contains(&0) {
            return Err(FfiError::invalid(format!("dimensions {nx}x{ny}x{nz}: each must be at least 1")));
        }
        if dims.iter().any(|&d| d > MAX_DENSE_SIDE) {
            return Err(FfiError::new(VsStatus::TooLarge, format!("dimensions {nx}x{ny}x{nz}: each must be at most {MAX_DENSE_SIDE}")));
        }
        let count = nx as u64 * ny as u64 * nz as u64;
        let limits = GridLimits::default();
        if count > limits.max_extent_voxels {
            return Err(FfiError::new(
                VsStatus::TooLarge,
                format!("dimensions {nx}x{ny}x{nz} = {count} voxels, over the limit of {}", limits.max_extent_voxels),
            ));
        }
        if len as u64 != count {
            return Err(FfiError::buffer(format!("density holds {len} floats; {nx}x{ny}x{nz} needs {count}")));
        }
        let values = in_slice(density, len, "density")?;
        let i2w = affine_arg(index_to_world, "index_to_world")?;
        let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::new(nx as i32, ny as i32, nz as i32), values, limits)?;
        let mut st = lock(&h.state);
        let m = &st.scene.medium;
        let medium = Medium::new(grid, i2w, m.density_scale, m.albedo, m.g);
        st.edit().medium = medium;
        st.has_medium = true;
        Ok(())
    })
}

/// Sets the medium's material: extinction per unit density `density_scale` (3 floats, RGB,
/// 1/m, >= 0), single-scattering `albedo` (3 floats in [0, 1]) and Henyey-Greenstein `g` in
/// (-1, 1). Applies to the current and any later medium of this scene. A new scene starts
/// with density_scale 1, albedo 1, g 0.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_material(scene: *mut VsScene, density_scale: *const f32, albedo: *const f32, g: f32) -> VsStatus {
    edit_scene(scene, |st| {
        let ds: [f32; 3] = floats_arg(density_scale, "density_scale")?;
        let al: [f32; 3] = floats_arg(albedo, "albedo")?;
        if ds.iter().any(|v| *v < 0.0) {
            return Err(FfiError::invalid(format!("density_scale {ds:?}: must be >= 0")));
        }
        if al.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(FfiError::invalid(format!("albedo {al:?}: must be in [0, 1]")));
        }
        let g = finite_arg(g, "g")?;
        if !(g > -1.0 && g < 1.0) {
            return Err(FfiError::invalid(format!("g is {g}: must be in (-1, 1)")));
        }
        let m = &mut st.edit().medium;
        m.density_scale = Vec3::from(ds);
        m.albedo = Vec3::from(al);
        m.g = g;
        Ok(())
    })
}

// ---- lights -------------------------------------------------------------------------------

fn add_light(scene: *mut VsScene, make: impl FnOnce() -> FfiResult<LightJson>) -> VsStatus {
    edit_scene(scene, |st| {
        let json = make()?;
        let field = format!("lights[{}]", st.scene.lights.len());
        let light = scene::build_light(&json, &field, Path::new("."))?;
        st.edit().lights.push(light);
        Ok(())
    })
}

/// Removes all lights.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_clear_lights(scene: *mut VsScene) -> VsStatus {
    edit_scene(scene, |st| {
        st.edit().lights.clear();
        Ok(())
    })
}

/// Adds a distant (sun) light: `direction` (3 floats, not zero) is the direction light
/// travels, `irradiance` (3 floats, RGB, W/m^2, >= 0) is measured perpendicular to it, and
/// `angle_deg` in [0, 180) is the apparent diameter of its disc (0: a delta direction).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_distant_light(scene: *mut VsScene, direction: *const f32, irradiance: *const f32, angle_deg: f32) -> VsStatus {
    add_light(scene, || {
        Ok(LightJson::Distant {
            direction: floats_arg(direction, "direction")?,
            irradiance: rgb(floats_arg(irradiance, "irradiance")?),
            angle_deg: finite_arg(angle_deg, "angle_deg")?,
        })
    })
}

/// Adds a point light at `position` (3 floats, world metres) with `intensity` (3 floats, RGB,
/// W/sr, >= 0); `radius` > 0 makes it a sphere light of the same power (0: a point).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_point_light(scene: *mut VsScene, position: *const f32, intensity: *const f32, radius: f32) -> VsStatus {
    add_light(scene, || {
        Ok(LightJson::Point {
            position: floats_arg(position, "position")?,
            intensity: rgb(floats_arg(intensity, "intensity")?),
            radius: finite_arg(radius, "radius")?,
            interior: Default::default(),
        })
    })
}

/// Adds a spot light at `position` (3 floats, world metres) pointing along `direction` (3
/// floats, not zero) with `intensity` (3 floats, RGB, W/sr, >= 0) on its axis, zero outside the
/// cone of half-angle `cone_half_angle_deg` in (0, 180]. `blend` in [0, 1] softens the outer
/// fraction of the cone (Cycles' spot blend: a smoothstep in the cosine from cos(half-angle)
/// to cos(half-angle) + (1 - cos(half-angle)) * blend); `radius` >= 0 makes it a sphere of that
/// radius (0: a point).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_spot_light(
    scene: *mut VsScene,
    position: *const f32,
    direction: *const f32,
    intensity: *const f32,
    cone_half_angle_deg: f32,
    blend: f32,
    radius: f32,
) -> VsStatus {
    add_light(scene, || {
        Ok(LightJson::Spot {
            position: floats_arg(position, "position")?,
            direction: floats_arg(direction, "direction")?,
            intensity: rgb(floats_arg(intensity, "intensity")?),
            cone_half_angle_deg: finite_arg(cone_half_angle_deg, "cone_half_angle_deg")?,
            blend: finite_arg(blend, "blend")?,
            radius: finite_arg(radius, "radius")?,
        })
    })
}

/// Adds a one-sided rectangular area light centred at `position` (3 floats, world metres),
/// emitting towards `normal` (3 floats, not zero) with uniform `radiance` (3 floats, RGB,
/// W/m^2/sr, >= 0; power pi * radiance * width * height). `width` (> 0) runs along `tangent`
/// (3 floats, made perpendicular to the normal; NULL: any direction perpendicular to it),
/// `height` (> 0) along normal x tangent.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_rect_light(
    scene: *mut VsScene,
    position: *const f32,
    normal: *const f32,
    tangent: *const f32,
    width: f32,
    height: f32,
    radiance: *const f32,
) -> VsStatus {
    add_light(scene, || {
        Ok(LightJson::Rect {
            position: floats_arg(position, "position")?,
            normal: floats_arg(normal, "normal")?,
            tangent: if tangent.is_null() { None } else { Some(floats_arg(tangent, "tangent")?) },
            size: [finite_arg(width, "width")?, finite_arg(height, "height")?],
            radiance: rgb(floats_arg(radiance, "radiance")?),
        })
    })
}

/// Adds a one-sided disc area light centred at `position` (3 floats, world metres), emitting
/// towards `normal` (3 floats, not zero), of `radius` (> 0) and uniform `radiance` (3 floats,
/// RGB, W/m^2/sr, >= 0; power pi * radiance * pi * radius^2).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_disk_light(scene: *mut VsScene, position: *const f32, normal: *const f32, radius: f32, radiance: *const f32) -> VsStatus {
    add_light(scene, || {
        Ok(LightJson::Disk {
            position: floats_arg(position, "position")?,
            normal: floats_arg(normal, "normal")?,
            radius: finite_arg(radius, "radius")?,
            radiance: rgb(floats_arg(radiance, "radiance")?),
        })
    })
}

/// Adds a uniform dome (environment) light of radiance `color` (3 floats, RGB, W/m^2/sr, >= 0).
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_dome_light(scene: *mut VsScene, color: *const f32) -> VsStatus {
    add_light(scene, || Ok(LightJson::Dome { color: Some(rgb(floats_arg(color, "color")?)), texture: None, intensity: 1.0 }))
}

/// Adds a dome light from a lat-long environment map (EXR, Blender's equirectangular layout,
/// Z up) at `path` (UTF-8; relative to the current directory) times `intensity` (>= 0).
///
/// Thread safety: any thread; calls on one scene are serialised (the map is read with the
/// scene locked).
#[no_mangle]
pub unsafe extern "C" fn vs_scene_add_dome_texture(scene: *mut VsScene, path: *const c_char, intensity: f32) -> VsStatus {
    add_light(scene, || {
        let intensity = finite_arg(intensity, "intensity")?;
        input_file_arg(path, "path", GridLimits::default().max_bytes)?;
        let path = str_arg(path, "path")?;
        Ok(LightJson::Dome { color: None, texture: Some(path.to_string()), intensity })
    })
}

/// Writes the number of lights to `*out`.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_light_count(scene: *const VsScene, out: *mut usize) -> VsStatus {
    on_handle(&SCENES, scene, |h| write_out(out, lock(&h.state).scene.lights.len(), "out"))
}

// ---- camera and solver --------------------------------------------------------------------

/// Sets the pinhole camera: `position`, `look_at` and `up` (3 floats each; `up` NULL: +Z),
/// horizontal field of view `fov_deg` in (0, 179), and the image size in pixels (each side
/// 1..=16384, at most 2^26 pixels). The scattering grid is computed towards this camera.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_camera(
    scene: *mut VsScene,
    position: *const f32,
    look_at: *const f32,
    up: *const f32,
    fov_deg: f32,
    width: u32,
    height: u32,
) -> VsStatus {
    edit_scene(scene, |st| {
        let json = CameraJson {
            position: floats_arg(position, "position")?,
            look_at: floats_arg(look_at, "look_at")?,
            up: if up.is_null() { [0.0, 0.0, 1.0] } else { floats_arg(up, "up")? },
            fov_deg: finite_arg(fov_deg, "fov_deg")?,
            width,
            height,
        };
        let camera = scene::build_camera(&json)?;
        st.edit().camera = camera;
        st.has_camera = true;
        Ok(())
    })
}

/// Chooses where GPU-capable stages run for this scene and the results solved from it:
/// `VS_DEVICE_CPU` (0, the default), `VS_DEVICE_GPU` (1: any adapter, a software one such as
/// Mesa's lavapipe included; fail with `VS_STATUS_DEVICE` when none works) or `VS_DEVICE_AUTO`
/// (2: a hardware GPU adapter when one works, else the CPU; never a software adapter, which is
/// slower than the CPU solvers). A GPU that is lost or runs out of memory mid-way falls back to
/// the CPU under AUTO. On the GPU run: the stages of solvers with a GPU backend (the "gpu" flag
/// of `vs_solvers_json`; today pop's propagation, `vs_scene_solve`) and the compositor
/// (`vs_result_composite`). Other values are refused.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_device(scene: *mut VsScene, device: u32) -> VsStatus {
    let choice = match device {
        VS_DEVICE_CPU => DeviceChoice::Cpu,
        VS_DEVICE_GPU => DeviceChoice::Gpu,
        VS_DEVICE_AUTO => DeviceChoice::Auto,
        other => {
            return with_scene(scene, |_| Err(FfiError::invalid(format!("device {other} is not a VS_DEVICE_* value (0 cpu, 1 gpu, 2 auto)"))))
        }
    };
    with_scene(scene, |h| {
        lock(&h.state).device = choice;
        Ok(())
    })
}

/// Chooses the solver by `name` ("reference", "pop", ...) with its settings as a JSON object
/// (`settings_json` NULL or "": defaults), e.g. `{"grid_resolution": 32, "seed": 1}`. The
/// settings are validated now: unknown solvers and keys are refused and the scene unchanged.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_set_solver(scene: *mut VsScene, name: *const c_char, settings_json: *const c_char) -> VsStatus {
    edit_scene(scene, |st| {
        let name = str_arg(name, "name")?;
        let text = opt_str_arg(settings_json, "settings_json")?.unwrap_or("");
        let mut settings = if text.trim().is_empty() {
            serde_json::Map::new()
        } else {
            match serde_json::from_str::<serde_json::Value>(text) {
                Ok(serde_json::Value::Object(m)) => m,
                Ok(_) => return Err(FfiError::invalid("settings_json must be a JSON object")),
                Err(e) => return Err(FfiError::invalid(format!("settings_json: {e}"))),
            }
        };
        settings.insert("name".into(), serde_json::Value::String(name.to_string()));
        registry::get(name)?.validate(&settings)?;
        st.edit().solver = settings;
        Ok(())
    })
}

// ---- solving ------------------------------------------------------------------------------

/// Runs the scene's solver (the one chosen by `vs_scene_set_solver` or the scene JSON;
/// default "reference") and puts the scattering grid in a new result `*out` (NULL on failure;
/// destroy with `vs_result_destroy`). `progress` (may be NULL) is called with `user` as work
/// proceeds and can cancel (`VS_STATUS_CANCELLED`). Needs a medium and a camera.
///
/// Thread safety: any thread. The solve works on a snapshot of the scene and does not hold
/// the scene locked: other calls on the same scene (edits, other solves) proceed meanwhile.
/// Solves of independent scenes run in parallel, sharing one worker pool.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_solve(scene: *mut VsScene, progress: VsProgressCallback, user: *mut c_void, out: *mut *mut VsResult) -> VsStatus {
    with_scene(scene, |h| {
        clear_out(out, "out")?;
        let (snapshot, device) = {
            let st = lock(&h.state);
            (st.snapshot()?, st.device)
        };
        let progress = CProgress::new(progress, user);
        // A GPU failure is `Error::Device`, hence VS_STATUS_DEVICE (under AUTO it ran on the CPU).
        let mut session = pipeline::Session::for_scene(&snapshot, volscatter_gpu::devices(device))?;
        let solved = progress.with_heartbeat(|| session.solve(&snapshot, &progress))?;
        if progress.cancelled() {
            return Err(FfiError::new(VsStatus::Cancelled, "cancelled"));
        }
        let state = ResultState::new(solved, snapshot, device)?;
        write_out(out, RESULTS.insert(state)?, "out")
    })
}

/// Path-traces the scene's image directly with the reference solver (RGBA plus AOVs
/// "single", "multiple", "background") into a new image `*out` (NULL on failure; destroy with
/// `vs_image_destroy`). Uses the scene's solver settings when its solver is "reference" (or
/// unset), else the reference defaults. Deterministic for a seed. `progress` as for
/// `vs_scene_solve`.
///
/// Thread safety: as `vs_scene_solve`.
#[no_mangle]
pub unsafe extern "C" fn vs_scene_render_reference(scene: *mut VsScene, progress: VsProgressCallback, user: *mut c_void, out: *mut *mut VsImage) -> VsStatus {
    with_scene(scene, |h| {
        clear_out(out, "out")?;
        let snapshot = lock(&h.state).snapshot()?;
        let settings = match snapshot.solver_name() {
            None | Some("reference") => snapshot.solver.clone(),
            Some(_) => Default::default(),
        };
        let mut session = pipeline::Session::new("reference", &settings, pipeline::Devices::cpu())?;
        let progress = CProgress::new(progress, user);
        let opts = CompositeOptions::default();
        let image = progress.with_heartbeat(|| pipeline::render(&mut session, &snapshot, &opts, &progress))?.image;
        if progress.cancelled() {
            return Err(FfiError::new(VsStatus::Cancelled, "cancelled"));
        }
        write_out(out, IMAGES.insert(ImageState::new(image)?)?, "out")
    })
}

#[cfg(test)]
#[path = "lpm_estimate_tests.rs"]
mod lpm_estimate_tests;
