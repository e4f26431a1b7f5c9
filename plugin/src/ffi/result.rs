//! `VsResult`: the scattering grid a solve produced, with the scene snapshot it was solved for
//! (so that compositing uses the same medium and camera).

use std::ffi::{c_char, CString};
use std::sync::Arc;

use volscatter_core::compositor::{Aovs, CompositeOptions};
use volscatter_core::pipeline::{self, Solved};
use volscatter_core::stages::{ScatteringGrid, Timings};
use volscatter_core::{vdb, Scene};
use volscatter_gpu::{DeviceChoice, DeviceUsed};

use super::guard::{self, clear_out, finite_arg, on_handle, out_slice, path_arg, write_out};
use super::handle::{lock, Handle, Registry};
use super::image::{ImageState, IMAGES};
use super::status::{FfiError, FfiResult, VsStatus};
use super::version::{VS_COMPOSITE_TRANSPARENT, VS_DEVICE_CPU, VS_DEVICE_GPU};
use super::VsImage;

/// Opaque result handle, made by `vs_scene_solve`, destroyed with `vs_result_destroy`.
pub struct VsResult {
    _private: [u8; 0],
}

/// AOV bit for `vs_result_composite_aovs`: the `single` layer (single scattering, from the
/// compositor's own shadow rays). It and `VS_AOV_MULTIPLE` cost a second light pass over the
/// medium (more than the march); without either it is not computed.
pub const VS_AOV_SINGLE: u32 = 1;
/// AOV bit for `vs_result_composite_aovs`: the `multiple` layer (what was scattered minus the
/// `single` layer; needs the same light pass as `VS_AOV_SINGLE`).
pub const VS_AOV_MULTIPLE: u32 = 2;
/// AOV bit for `vs_result_composite_aovs`: the `background` layer (the environment seen
/// through the medium; free, the march computes it anyway).
pub const VS_AOV_BACKGROUND: u32 = 4;
/// AOV bit for `vs_result_composite_aovs`: the `emission` layer (the medium's own emission
/// seen directly; free, the march computes it anyway; part of the RGBA image).
pub const VS_AOV_EMISSION: u32 = 8;
/// Every AOV bit: what `vs_result_composite` makes.
pub const VS_AOV_ALL: u32 = VS_AOV_SINGLE | VS_AOV_MULTIPLE | VS_AOV_BACKGROUND | VS_AOV_EMISSION;

/// File formats for `vs_result_write_grid` (passed as `uint32_t`; other values are refused).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VsGridFormat {
    /// OpenEXR image, float RGB, width nx, height ny * nz: z slice k occupies rows
    /// k * ny .. (k + 1) * ny, row j of the slice is grid row j. Attributes `volscatterDims`
    /// (text "nx ny nz") and `volscatterIndexToWorld` (4x4 matrix, row-major) describe the grid.
    Exr = 1,
    /// OpenVDB file (version 224, Zip) with three float grids `scattering_r`, `scattering_g`,
    /// `scattering_b` (what Blender and USD read) and the grid's transform.
    Vdb = 2,
}

impl VsGridFormat {
    /// Converts a C integer, never by transmute.
    pub(crate) fn from_u32(v: u32) -> FfiResult<Self> {
        match v {
            1 => Ok(VsGridFormat::Exr),
            2 => Ok(VsGridFormat::Vdb),
            other => Err(FfiError::invalid(format!("format {other} is not a VsGridFormat (1 = EXR, 2 = VDB)"))),
        }
    }
}

pub(crate) struct ResultState {
    pub grid: ScatteringGrid,
    pub scene: Arc<Scene>,
    /// The scene's device choice when it was solved (used by `vs_result_composite`).
    pub device: DeviceChoice,
    /// Where the solve actually ran (`vs_result_device`): under AUTO, or for a solver without a
    /// GPU backend, the CPU even though the GPU was allowed.
    pub used: DeviceUsed,
    #[allow(dead_code)]
    pub timings: Timings,
    /// What the `auto` solver picked and why, as JSON (`vs_result_choice`); None from the
    /// other solvers.
    pub choice: Option<CString>,
    /// What the host should tell the user, one note a line (`vs_result_notes`).
    pub notes: CString,
}

impl ResultState {
    pub fn new(solved: Solved, scene: Arc<Scene>, device: DeviceChoice) -> FfiResult<Self> {
        let Solved { output, choice, device: used, notes, .. } = solved;
        let g = &output.scattering;
        let count = g.dims.iter().map(|&d| d as u64).product::<u64>();
        if count != g.data.len() as u64 {
            return Err(FfiError::new(
                VsStatus::Internal,
                format!("solver returned a {:?} grid with {} values", g.dims, g.data.len()),
            ));
        }
        // serde_json escapes control characters, so the JSON has no interior NUL; were it to,
        // the choice is dropped rather than the result.
        let choice = choice.as_ref().and_then(|c| serde_json::to_string(c).ok()).and_then(|j| CString::new(j).ok());
        let notes = CString::new(notes.join("\n").replace('\0', " ")).unwrap_or_default();
        Ok(ResultState { grid: output.scattering, scene, device, used, timings: output.timings, choice, notes })
    }
    fn float_count(&self) -> usize {
        self.grid.data.len() * 3
    }
}

pub(crate) static RESULTS: Registry<ResultState, VsResult> = Registry::new("VsResult");

fn with_result(result: *const VsResult, body: impl FnOnce(&ResultState) -> FfiResult) -> VsStatus {
    on_handle(&RESULTS, result, |h: &Arc<Handle<ResultState>>| body(&lock(&h.state)))
}

/// Destroys a result. NULL is ignored; a dead handle gives `VS_STATUS_INVALID_HANDLE`.
///
/// Thread safety: any thread; the handle must not be used afterwards.
#[no_mangle]
pub unsafe extern "C" fn vs_result_destroy(result: *mut VsResult) -> VsStatus {
    guard::call(|| if result.is_null() { Ok(()) } else { RESULTS.remove(result) })
}

/// The message of the last failed call on this result ("" after a success); valid until the
/// next call on it or its destruction. For a NULL or dead handle, a static description.
///
/// Thread safety: meaningful only when no other thread calls functions on this result meanwhile.
#[no_mangle]
pub unsafe extern "C" fn vs_result_last_error(result: *const VsResult) -> *const c_char {
    guard::value(VsStatus::Internal.description().as_ptr().cast(), || match RESULTS.get(result) {
        Ok(h) => h.error.as_ptr(),
        Err(e) => e.status.description().as_ptr().cast(),
    })
}

/// Writes the grid's dimensions (nx, ny, nz) to `dims` (3 values).
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_dims(result: *const VsResult, dims: *mut u32) -> VsStatus {
    with_result(result, |r| {
        let out = out_slice(dims, 3, 3, "dims")?;
        out.copy_from_slice(&r.grid.dims);
        Ok(())
    })
}

/// Writes where the solve that made this result ran to `*out`: `VS_DEVICE_CPU` (0) or
/// `VS_DEVICE_GPU` (1), never `VS_DEVICE_AUTO`. A scene set to GPU or AUTO still gives the CPU
/// for a solver without a GPU backend, and AUTO gives the CPU when no hardware adapter works.
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_device(result: *const VsResult, out: *mut u32) -> VsStatus {
    with_result(result, |r| {
        let code = match r.used {
            DeviceUsed::Cpu => VS_DEVICE_CPU,
            DeviceUsed::Gpu(_) => VS_DEVICE_GPU,
        };
        write_out(out, code, "out")
    })
}

/// What the `auto` solver picked for this result and why, as a JSON object: `solver`,
/// `quality`, `settings`, `predicted_error` (image rel. RMSE), `predicted_seconds`,
/// `target_error`, `time_budget`, `why` (a sentence), `fallback` (true when no measurement
/// covered the scene and the default ran). Owned by the result: valid until it is destroyed.
/// NULL for a result of another solver, and for a NULL or dead handle.
///
/// Thread safety: any thread.
#[no_mangle]
pub unsafe extern "C" fn vs_result_choice(result: *const VsResult) -> *const c_char {
    guard::value(std::ptr::null(), || match RESULTS.get(result) {
        Ok(h) => lock(&h.state).choice.as_ref().map_or(std::ptr::null(), |c| c.as_ptr()),
        Err(_) => std::ptr::null(),
    })
}

/// What the solve's pipeline has to tell the user (a fall-back from the GPU to the CPU, a light
/// a solver left out, a dome map read at a lower resolution), one note a line, UTF-8; "" when
/// there is nothing to say. Owned by the result: valid until it is destroyed. NULL for a NULL
/// or dead handle.
///
/// Thread safety: any thread.
#[no_mangle]
pub unsafe extern "C" fn vs_result_notes(result: *const VsResult) -> *const c_char {
    guard::value(std::ptr::null(), || match RESULTS.get(result) {
        Ok(h) => lock(&h.state).notes.as_ptr(),
        Err(_) => std::ptr::null(),
    })
}

/// Writes the number of floats `vs_result_copy_rgb` needs (nx * ny * nz * 3) to `*out`.
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_float_count(result: *const VsResult, out: *mut usize) -> VsStatus {
    with_result(result, |r| write_out(out, r.float_count(), "out"))
}

/// Writes the grid's index-to-world map to `matrix` (16 floats, row-major 4x4): grid point
/// (i, j, k) sits at `matrix * (i, j, k, 1)` in world metres.
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_index_to_world(result: *const VsResult, matrix: *mut f32) -> VsStatus {
    with_result(result, |r| {
        let out = out_slice(matrix, 16, 16, "matrix")?;
        out.copy_from_slice(&glam::Mat4::from(r.grid.index_to_world).transpose().to_cols_array());
        Ok(())
    })
}

/// Copies the scattering grid S (in-scattered radiance per metre towards the camera, W/m^3/sr,
/// linear RGB) into `rgb`: `len` must equal `vs_result_float_count` (nx * ny * nz * 3), the
/// values interleaved R, G, B, grid points x fastest, then y, then z.
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_copy_rgb(result: *const VsResult, rgb: *mut f32, len: usize) -> VsStatus {
    with_result(result, |r| {
        let out = out_slice(rgb, len, r.float_count(), "rgb")?;
        for (dst, v) in out.chunks_exact_mut(3).zip(&r.grid.data) {
            dst.copy_from_slice(&v.to_array());
        }
        Ok(())
    })
}

/// Writes the scattering grid to `path` in `format` (a `VsGridFormat` value; others give
/// `VS_STATUS_INVALID_ARGUMENT`).
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_write_grid(result: *const VsResult, path: *const c_char, format: u32) -> VsStatus {
    with_result(result, |r| {
        let path = path_arg(path, "path")?;
        match VsGridFormat::from_u32(format)? {
            VsGridFormat::Exr => super::grid_exr::write_grid(&path, &r.grid),
            VsGridFormat::Vdb => {
                let g = &r.grid;
                vdb::write_rgb_grids(&path, "scattering", g.dims, &g.data, g.index_to_world, &vdb::WriteOptions::default())?;
                Ok(())
            }
        }
    })
}

/// Composites the scattering grid into an image towards the scene's camera (ray marching S
/// with the medium's transmittance; alpha = 1 - transmittance) into a new image `*out` (NULL
/// on failure; destroy with `vs_image_destroy`), with every AOV layer ("single", "multiple",
/// "background"): the same as `vs_result_composite_aovs` with `VS_AOV_ALL`, kept for the
/// callers written before it. A caller that does not read "single" or "multiple" should call
/// `vs_result_composite_aovs` without them: they cost more than the rest of the composite.
/// `flags`: 0 or `VS_COMPOSITE_TRANSPARENT`; other bits are refused. `subpixels`: samples per
/// pixel axis, 1..=16 (0: default 2). `step_voxels`: march step in voxels, in [0.05, 8]
/// (0: default 0.5).
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_composite(result: *const VsResult, flags: u32, subpixels: u32, step_voxels: f32, out: *mut *mut VsImage) -> VsStatus {
    with_result(result, |r| composite_into(r, flags, VS_AOV_ALL, subpixels, step_voxels, out))
}

/// `vs_result_composite` with the AOV layers chosen: `aovs` is 0 (RGBA only) or a sum of
/// `VS_AOV_SINGLE`, `VS_AOV_MULTIPLE` and `VS_AOV_BACKGROUND` (other bits are refused); the
/// image carries exactly those layers, in that order. Without `VS_AOV_SINGLE` and
/// `VS_AOV_MULTIPLE` the single-scattering light pass is skipped. `flags`, `subpixels` and
/// `step_voxels` as for `vs_result_composite`.
///
/// Thread safety: any thread; calls on one result are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_result_composite_aovs(
    result: *const VsResult,
    flags: u32,
    aovs: u32,
    subpixels: u32,
    step_voxels: f32,
    out: *mut *mut VsImage,
) -> VsStatus {
    with_result(result, |r| composite_into(r, flags, aovs, subpixels, step_voxels, out))
}

/// The AOV set of a `VS_AOV_*` bit mask; unknown bits are refused, never ignored.
fn aovs_from_bits(aovs: u32) -> FfiResult<Aovs> {
    if aovs & !VS_AOV_ALL != 0 {
        return Err(FfiError::invalid(format!("aovs {aovs:#x}: unknown bits {:#x} (VS_AOV_SINGLE 1, VS_AOV_MULTIPLE 2, VS_AOV_BACKGROUND 4, VS_AOV_EMISSION 8)", aovs & !VS_AOV_ALL)));
    }
    Ok(Aovs {
        single: aovs & VS_AOV_SINGLE != 0,
        multiple: aovs & VS_AOV_MULTIPLE != 0,
        background: aovs & VS_AOV_BACKGROUND != 0,
        emission: aovs & VS_AOV_EMISSION != 0,
    })
}

unsafe fn composite_into(r: &ResultState, flags: u32, aovs: u32, subpixels: u32, step_voxels: f32, out: *mut *mut VsImage) -> FfiResult {
    clear_out(out, "out")?;
    if flags & !VS_COMPOSITE_TRANSPARENT != 0 {
        return Err(FfiError::invalid(format!("flags {flags:#x}: unknown bits {:#x}", flags & !VS_COMPOSITE_TRANSPARENT)));
    }
    let mut opts = CompositeOptions { transparent: flags & VS_COMPOSITE_TRANSPARENT != 0, aovs: aovs_from_bits(aovs)?, ..Default::default() };
    if subpixels != 0 {
        if subpixels > 16 {
            return Err(FfiError::invalid(format!("subpixels is {subpixels}: must be in 1..=16 (0: default)")));
        }
        opts.subpixels = subpixels;
    }
    let step = finite_arg(step_voxels, "step_voxels")?;
    if step != 0.0 {
        if !(0.05..=8.0).contains(&step) {
            return Err(FfiError::invalid(format!("step_voxels is {step}: must be in [0.05, 8] (0: default)")));
        }
        opts.step_voxels = step;
    }
    let image = pipeline::composite(&r.scene, &r.grid, &opts, volscatter_gpu::devices(r.device))?.image;
    write_out(out, IMAGES.insert(ImageState::new(image)?)?, "out")
}
