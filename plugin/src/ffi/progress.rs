//! The C progress callback, adapted to the solvers' `Progress` trait.

use std::ffi::{c_char, c_void, CString};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use volscatter_core::Progress;

use super::handle::lock;

/// Progress callback: `stage` names the current phase (valid only during the call), `fraction`
/// is in [0, 1] within that stage. Return non-zero to continue, 0 to cancel: the call that
/// is running then returns `VS_STATUS_CANCELLED` soon after.
///
/// It is called from the solver's worker threads, one call at a time (never concurrently for
/// one solve), possibly from a thread other than the caller's. It must not unwind (C++
/// exceptions, longjmp) through the library. It may call functions on other handles, and on
/// the scene being solved (the solve works on a snapshot taken when it started).
pub type VsProgressCallback = Option<unsafe extern "C" fn(user: *mut c_void, stage: *const c_char, fraction: f32) -> i32>;

pub(crate) struct CProgress {
    callback: VsProgressCallback,
    /// The host's pointer, passed back untouched; stored as an integer to be `Sync`.
    user: usize,
    /// Serialises callback calls and caches the last stage's C string.
    stage: Mutex<(String, CString)>,
    cancelled: AtomicBool,
}

impl CProgress {
    pub fn new(callback: VsProgressCallback, user: *mut c_void) -> Self {
        CProgress { callback, user: user as usize, stage: Mutex::new((String::new(), CString::default())), cancelled: AtomicBool::new(false) }
    }
    pub fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

impl Progress for CProgress {
    fn update(&self, stage: &str, fraction: f32) -> bool {
        if self.cancelled() {
            return false;
        }
        let Some(cb) = self.callback else { return true };
        let mut st = lock(&self.stage);
        if self.cancelled() {
            return false;
        }
        if st.0 != stage {
            st.0 = stage.to_string();
            st.1 = CString::new(stage.replace('\0', " ")).unwrap_or_default();
        }
        let fraction = if fraction.is_finite() { fraction.clamp(0.0, 1.0) } else { 0.0 };
        // SAFETY: the host gave this function pointer and user pointer for this call.
        let go_on = unsafe { cb(self.user as *mut c_void, st.1.as_ptr(), fraction) };
        if go_on == 0 {
            self.cancelled.store(true, Ordering::Relaxed);
            return false;
        }
        true
    }
}
