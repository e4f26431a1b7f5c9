//! Library and ABI versions.

use std::ffi::c_char;

/// The ABI version of this header. A host checks `vs_abi_version() == VS_ABI_VERSION` after
/// loading the library, and refuses to go on otherwise. It changes whenever a signature, a
/// struct layout or the meaning of an existing value changes; adding functions or status
/// values does not change it.
pub const VS_ABI_VERSION: u32 = 1;

/// Flag for `vs_result_composite`: leave the directly seen environment out (alpha from the
/// medium only), for compositing over other layers.
pub const VS_COMPOSITE_TRANSPARENT: u32 = 1;

const VERSION_C: &str = concat!(env!("CARGO_PKG_VERSION"), "\0");

/// The library version ("MAJOR.MINOR.PATCH"), a static NUL-terminated string.
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub extern "C" fn vs_version() -> *const c_char {
    super::guard::value(c"unknown".as_ptr().cast(), || VERSION_C.as_ptr().cast())
}

/// The ABI version the library was built with; compare with `VS_ABI_VERSION`.
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub extern "C" fn vs_abi_version() -> u32 {
    super::guard::value(VS_ABI_VERSION, || VS_ABI_VERSION)
}

/// `vs_scene_set_device`: run on the CPU (the default).
pub const VS_DEVICE_CPU: u32 = 0;
/// `vs_scene_set_device`: run on a GPU adapter; fail when none works.
pub const VS_DEVICE_GPU: u32 = 1;
/// `vs_scene_set_device`: a GPU adapter when one works, else the CPU.
pub const VS_DEVICE_AUTO: u32 = 2;
