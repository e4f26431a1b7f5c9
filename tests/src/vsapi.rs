//! libvolscatter loaded with libloading, as a plugin host loads it: every signature of
//! `plugin/include/volscatter.h` declared once, here.
// The helpers pass handles and library strings on; libvolscatter checks every handle itself
// (a dead or made-up one gives VS_STATUS_INVALID_HANDLE), which is what the tests exercise.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use std::ffi::{c_char, c_void, CStr, CString};
use std::path::Path;

use libloading::Library;

/// `VsStatus` values (checked against the header by `status_values_match_the_header`).
pub mod status {
    pub const OK: i32 = 0;
    pub const NULL_ARGUMENT: i32 = 1;
    pub const INVALID_ARGUMENT: i32 = 2;
    pub const INVALID_HANDLE: i32 = 3;
    pub const BUFFER_SIZE: i32 = 4;
    pub const INVALID_SCENE: i32 = 5;
    pub const IO: i32 = 6;
    pub const FORMAT: i32 = 7;
    pub const TOO_LARGE: i32 = 8;
    pub const UNSUPPORTED: i32 = 9;
    pub const CANCELLED: i32 = 10;
    pub const INTERNAL: i32 = 11;
    pub const DEVICE: i32 = 12;
    pub const BUSY: i32 = 13;
    pub const ALL: [(&str, i32); 14] = [
        ("VS_STATUS_OK", OK),
        ("VS_STATUS_NULL_ARGUMENT", NULL_ARGUMENT),
        ("VS_STATUS_INVALID_ARGUMENT", INVALID_ARGUMENT),
        ("VS_STATUS_INVALID_HANDLE", INVALID_HANDLE),
        ("VS_STATUS_BUFFER_SIZE", BUFFER_SIZE),
        ("VS_STATUS_INVALID_SCENE", INVALID_SCENE),
        ("VS_STATUS_IO", IO),
        ("VS_STATUS_FORMAT", FORMAT),
        ("VS_STATUS_TOO_LARGE", TOO_LARGE),
        ("VS_STATUS_UNSUPPORTED", UNSUPPORTED),
        ("VS_STATUS_CANCELLED", CANCELLED),
        ("VS_STATUS_INTERNAL", INTERNAL),
        ("VS_STATUS_DEVICE", DEVICE),
        ("VS_STATUS_BUSY", BUSY),
    ];
}

pub const ABI_VERSION: u32 = 1;
pub const GRID_FORMAT_EXR: u32 = 1;
pub const GRID_FORMAT_VDB: u32 = 2;
pub const COMPOSITE_TRANSPARENT: u32 = 1;

/// Opaque handles (`VsScene*`, `VsResult*`, `VsImage*`).
pub type Scene = *mut c_void;
pub type Res = *mut c_void;
pub type Img = *mut c_void;
pub type Sess = *mut c_void;
pub type Progress = Option<unsafe extern "C" fn(user: *mut c_void, stage: *const c_char, fraction: f32) -> i32>;

type S = i32;
type Cs = *const c_char;
type F = *const f32;

macro_rules! api {
    ($( $name:ident : fn($($arg:ty),*) -> $ret:ty; )*) => {
        /// The library and its functions; the pointers are valid while `Api` lives.
        pub struct Api {
            _lib: Library,
            $(pub $name: unsafe extern "C" fn($($arg),*) -> $ret,)*
        }
        impl Api {
            pub fn load(path: &Path) -> Result<Api, libloading::Error> {
                // SAFETY: libvolscatter runs no initialisers with preconditions; each symbol
                // is declared with the header's signature.
                unsafe {
                    let lib = Library::new(path)?;
                    $(let $name = *lib.get::<unsafe extern "C" fn($($arg),*) -> $ret>(concat!(stringify!($name), "\0").as_bytes())?;)*
                    Ok(Api { _lib: lib, $($name,)* })
                }
            }
            pub const NAMES: &'static [&'static str] = &[$(stringify!($name)),*];
        }
    };
}

api! {
    vs_version: fn() -> Cs;
    vs_abi_version: fn() -> u32;
    vs_status_message: fn(i32) -> Cs;
    // The memory budget (issue 22).
    vs_set_memory_budget: fn(u64) -> S;
    vs_memory_budget: fn() -> u64;
    vs_scene_new: fn(*mut Scene) -> S;
    vs_scene_destroy: fn(Scene) -> S;
    vs_scene_last_error: fn(Scene) -> Cs;
    vs_scene_load_json: fn(Scene, Cs, Cs) -> S;
    vs_scene_load_file: fn(Scene, Cs) -> S;
    vs_scene_load_default: fn(Scene) -> S;
    vs_scene_set_medium_vdb: fn(Scene, Cs, Cs, F) -> S;
    // The lpm estimate of a VDB medium (issue 19): out is a VsLpmEstimate, 11 uint64.
    vs_scene_lpm_estimate: fn(Scene, Cs, Cs, F, u32, Cs, *mut [u64; 11]) -> S;
    vs_scene_set_medium_dense: fn(Scene, F, usize, u32, u32, u32, F) -> S;
    vs_scene_set_material: fn(Scene, F, F, f32) -> S;
    vs_scene_clear_lights: fn(Scene) -> S;
    vs_scene_add_distant_light: fn(Scene, F, F, f32) -> S;
    vs_scene_add_point_light: fn(Scene, F, F, f32) -> S;
    vs_scene_add_spot_light: fn(Scene, F, F, F, f32, f32, f32) -> S;
    vs_scene_add_rect_light: fn(Scene, F, F, F, f32, f32, F) -> S;
    vs_scene_add_disk_light: fn(Scene, F, F, f32, F) -> S;
    vs_scene_add_dome_light: fn(Scene, F) -> S;
    vs_scene_add_dome_texture: fn(Scene, Cs, f32) -> S;
    vs_scene_light_count: fn(Scene, *mut usize) -> S;
    vs_scene_set_camera: fn(Scene, F, F, F, f32, u32, u32) -> S;
    vs_scene_set_solver: fn(Scene, Cs, Cs) -> S;
    vs_scene_set_device: fn(Scene, u32) -> S;
    vs_scene_solve: fn(Scene, Progress, *mut c_void, *mut Res) -> S;
    vs_scene_render_reference: fn(Scene, Progress, *mut c_void, *mut Img) -> S;
    vs_result_destroy: fn(Res) -> S;
    vs_result_last_error: fn(Res) -> Cs;
    vs_result_dims: fn(Res, *mut u32) -> S;
    vs_result_device: fn(Res, *mut u32) -> S;
    vs_result_choice: fn(Res) -> Cs;
    vs_result_notes: fn(Res) -> Cs;
    vs_result_float_count: fn(Res, *mut usize) -> S;
    vs_result_index_to_world: fn(Res, *mut f32) -> S;
    vs_result_copy_rgb: fn(Res, *mut f32, usize) -> S;
    vs_result_write_grid: fn(Res, Cs, u32) -> S;
    vs_result_composite: fn(Res, u32, u32, f32, *mut Img) -> S;
    vs_session_new: fn(Scene, *mut Sess) -> S;
    vs_session_destroy: fn(Sess) -> S;
    vs_session_last_error: fn(Sess) -> Cs;
    vs_session_solve: fn(Sess, Scene, Progress, *mut c_void, *mut Res) -> S;
    vs_session_frame_count: fn(Sess, *mut u64) -> S;
    vs_result_composite_aovs: fn(Res, u32, u32, u32, f32, *mut Img) -> S;
    vs_image_destroy: fn(Img) -> S;
    vs_image_last_error: fn(Img) -> Cs;
    vs_image_size: fn(Img, *mut u32, *mut u32) -> S;
    vs_image_copy_rgba: fn(Img, *mut f32, usize) -> S;
    vs_image_copy_aov: fn(Img, Cs, *mut f32, usize) -> S;
    vs_image_write_exr: fn(Img, Cs) -> S;
    // The solver registry (issue 14).
    vs_solvers_json: fn(*mut Cs) -> S;
    // VDB files for hosts (plugin/src/ffi/vdb_io.rs): grids is a VsVdbGrid array, copies a
    // VsVdbGridCopy array.
    vs_vdb_info_json: fn(Scene, Cs, u32, *mut c_char, usize, *mut usize) -> S;
    vs_vdb_write_grids: fn(Scene, Cs, *const u32, *const f64, *const c_void, usize, *const c_void, usize) -> S;
}

/// Copies a C string returned by the library (NULL becomes "<NULL>").
pub fn text(p: *const c_char) -> String {
    if p.is_null() {
        return "<NULL>".into();
    }
    // SAFETY: the library returns NUL-terminated strings valid until the next call.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

pub fn cstr(s: &str) -> CString {
    CString::new(s).expect("no NUL in test strings")
}

impl Api {
    pub fn scene_error(&self, s: Scene) -> String {
        text(unsafe { (self.vs_scene_last_error)(s) })
    }
    pub fn result_error(&self, r: Res) -> String {
        text(unsafe { (self.vs_result_last_error)(r) })
    }
    pub fn session_error(&self, s: Sess) -> String {
        text(unsafe { (self.vs_session_last_error)(s) })
    }
    pub fn image_error(&self, i: Img) -> String {
        text(unsafe { (self.vs_image_last_error)(i) })
    }
    pub fn status_message(&self, s: i32) -> String {
        text(unsafe { (self.vs_status_message)(s) })
    }
    pub fn new_scene(&self) -> Scene {
        let mut s: Scene = std::ptr::null_mut();
        assert_eq!(unsafe { (self.vs_scene_new)(&mut s) }, status::OK);
        assert!(!s.is_null());
        s
    }
    /// A scene loaded from JSON text; panics with the library's message on failure.
    pub fn scene_from_json(&self, json: &str) -> Scene {
        let s = self.new_scene();
        let st = unsafe { (self.vs_scene_load_json)(s, cstr(json).as_ptr(), std::ptr::null()) };
        assert_eq!(st, status::OK, "{}", self.scene_error(s));
        s
    }
    /// Solves; panics with the message on failure.
    pub fn solve(&self, s: Scene) -> Res {
        let mut r: Res = std::ptr::null_mut();
        let st = unsafe { (self.vs_scene_solve)(s, None, std::ptr::null_mut(), &mut r) };
        assert_eq!(st, status::OK, "{}", self.scene_error(s));
        r
    }
    /// The grid's dims and RGB floats.
    pub fn grid(&self, r: Res) -> ([u32; 3], Vec<f32>) {
        let mut dims = [0u32; 3];
        assert_eq!(unsafe { (self.vs_result_dims)(r, dims.as_mut_ptr()) }, status::OK, "{}", self.result_error(r));
        let mut n = 0usize;
        assert_eq!(unsafe { (self.vs_result_float_count)(r, &mut n) }, status::OK);
        let mut data = vec![0f32; n];
        assert_eq!(unsafe { (self.vs_result_copy_rgb)(r, data.as_mut_ptr(), n) }, status::OK, "{}", self.result_error(r));
        (dims, data)
    }
}
