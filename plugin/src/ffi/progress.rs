//! The C progress callback, adapted to the solvers' `Progress` trait, with a heartbeat: the
//! host hears from a solve at least every `HEARTBEAT` (100 ms) even while a solver is inside a
//! long stage that reports rarely (the reference's rows, a propagation sweep), so that it can
//! update its UI and cancel.

use std::ffi::{c_char, c_void, CString};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use volscatter_core::Progress;

use super::handle::lock;

/// Progress callback: `stage` names the current phase (valid only during the call), `fraction`
/// is in [0, 1] within that stage. Return non-zero to continue, 0 to cancel: the call that
/// is running then returns `VS_STATUS_CANCELLED` soon after.
///
/// It is called at least every 100 ms while a solve or render runs (repeating the last stage
/// and fraction when the solver has nothing new), from the solver's worker threads or a
/// heartbeat thread of the library, one call at a time (never concurrently for one solve),
/// possibly from a thread other than the caller's, and never after the call that was given it
/// returned. It must not unwind (C++ exceptions, longjmp) through the library. It may call
/// functions on other handles, and on the scene being solved (the solve works on a snapshot
/// taken when it started); on the session being solved, `vs_session_frame_count` answers and
/// `vs_session_solve` returns `VS_STATUS_BUSY` (it never waits inside a callback).
pub type VsProgressCallback = Option<unsafe extern "C" fn(user: *mut c_void, stage: *const c_char, fraction: f32) -> i32>;

thread_local! {
    /// Progress callbacks running on this thread now (a callback may start another solve).
    static IN_CALLBACK: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
}

/// Whether this thread is inside a host's progress callback: such a caller must never wait
/// for a solve, which may be waiting for the callback to return.
pub(crate) fn in_callback() -> bool {
    IN_CALLBACK.with(|c| c.get() > 0)
}

/// Marks this thread as inside a callback for as long as it lives (a drop: unwinding counts too).
struct InCallback;
impl InCallback {
    fn enter() -> Self {
        IN_CALLBACK.with(|c| c.set(c.get() + 1));
        InCallback
    }
}
impl Drop for InCallback {
    fn drop(&mut self) {
        IN_CALLBACK.with(|c| c.set(c.get().saturating_sub(1)));
    }
}

/// The host hears from a solve at least this often.
pub(crate) const HEARTBEAT: Duration = Duration::from_millis(100);

/// What the last callback said, and when.
struct Last {
    stage: String,
    c_stage: CString,
    fraction: f32,
    at: Instant,
}

pub(crate) struct CProgress {
    callback: VsProgressCallback,
    /// The host's pointer, passed back untouched; stored as an integer to be `Sync`.
    user: usize,
    /// Serialises callback calls; the last stage (with its cached C string) and fraction.
    last: Mutex<Last>,
    cancelled: AtomicBool,
}

impl CProgress {
    pub fn new(callback: VsProgressCallback, user: *mut c_void) -> Self {
        let last = Last { stage: String::new(), c_stage: CString::new("starting").unwrap_or_default(), fraction: 0.0, at: Instant::now() };
        CProgress { callback, user: user as usize, last: Mutex::new(last), cancelled: AtomicBool::new(false) }
    }
    pub fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }

    /// Calls the host with `last` (already locked, so calls never overlap).
    fn call(&self, last: &mut Last) -> bool {
        let Some(cb) = self.callback else { return true };
        last.at = Instant::now();
        let _inside = InCallback::enter();
        // SAFETY: the host gave this function pointer and user pointer for this call.
        let go_on = unsafe { cb(self.user as *mut c_void, last.c_stage.as_ptr(), last.fraction) };
        if go_on == 0 {
            self.cancelled.store(true, Ordering::Relaxed);
            return false;
        }
        true
    }

    /// Runs `work` while a heartbeat thread calls the host every `HEARTBEAT` that the solver
    /// itself did not (and records a cancel for the solver's next `update` or `cancelled`).
    /// The heartbeat is joined before this returns, panics in `work` included.
    pub fn with_heartbeat<T>(&self, work: impl FnOnce() -> T) -> T {
        if self.callback.is_none() {
            return work();
        }
        let stop = (Mutex::new(false), Condvar::new());
        /// Wakes the heartbeat to stop when `work` ends, by return or by panic.
        struct Stop<'a>(&'a (Mutex<bool>, Condvar));
        impl Drop for Stop<'_> {
            fn drop(&mut self) {
                *lock(&self.0 .0) = true;
                self.0 .1.notify_all();
            }
        }
        std::thread::scope(|s| {
            s.spawn(|| {
                let mut stopped = lock(&stop.0);
                loop {
                    // Wake at a third of the period, so that the gap stays under it.
                    stopped = match stop.1.wait_timeout(stopped, HEARTBEAT / 3) {
                        Ok((g, _)) => g,
                        Err(poisoned) => poisoned.into_inner().0,
                    };
                    if *stopped || self.cancelled() {
                        return;
                    }
                    let mut last = lock(&self.last);
                    if last.at.elapsed() >= HEARTBEAT * 2 / 3 {
                        self.call(&mut last);
                    }
                }
            });
            let _stop = Stop(&stop);
            work()
        })
    }
}

impl Progress for CProgress {
    fn update(&self, stage: &str, fraction: f32) -> bool {
        if self.cancelled() {
            return false;
        }
        if self.callback.is_none() {
            return true;
        }
        let mut last = lock(&self.last);
        if self.cancelled() {
            return false;
        }
        if last.stage != stage {
            last.stage = stage.to_string();
            last.c_stage = CString::new(stage.replace('\0', " ")).unwrap_or_default();
        }
        last.fraction = if fraction.is_finite() { fraction.clamp(0.0, 1.0) } else { 0.0 };
        self.call(&mut last)
    }

    fn cancelled(&self) -> bool {
        CProgress::cancelled(self)
    }
}
