//! The solver registry for hosts: the same JSON as `volscatter solvers`, so that a host builds
//! its solver menu, presets and light checks from the library it loaded.

use std::ffi::{c_char, CString};
use std::sync::OnceLock;

use volscatter_core::solvers::registry;

use super::guard::{self, write_out};
use super::status::{FfiError, VsStatus};

/// The registry's JSON, built once: the registry is fixed for the library's lifetime.
fn solvers_json() -> Result<&'static CString, FfiError> {
    static JSON: OnceLock<Option<CString>> = OnceLock::new();
    JSON.get_or_init(|| CString::new(registry::to_json().to_string()).ok())
        .as_ref()
        .ok_or_else(|| FfiError::new(VsStatus::Internal, "the solver registry's JSON contains a NUL byte"))
}

/// Sets `*out` to the solver registry as JSON (UTF-8, NUL-terminated):
/// `{"format": 1, "solvers": [{"name", "label", "help", "gpu", "lights", "settings", "presets"}, ...],
/// "light_types": [{"name", "help"}, ...]}`. Each setting has "name", "type" ("int", "float",
/// "bool", "choice"), "default", "help" and, where limited, "range" ({"min", "max",
/// "min_exclusive", "max_exclusive"}), "zero" (what 0 stands for) or "choices". "lights" names
/// the scene JSON light types the solver handles ("emission": an emissive medium). The first
/// solver is the default of hosts' menus. The string is static: valid as long as the library is
/// loaded, never to be freed. `*out` is NULL on failure.
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub unsafe extern "C" fn vs_solvers_json(out: *mut *const c_char) -> VsStatus {
    guard::call(|| {
        if out.is_null() {
            return Err(FfiError::null("out"));
        }
        out.write_unaligned(std::ptr::null());
        write_out(out, solvers_json()?.as_ptr(), "out")
    })
}
