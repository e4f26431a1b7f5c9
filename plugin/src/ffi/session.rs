//! `VsSession`: one solver kept across the solves of a sequence (frames of a VDB sequence, a
//! moving light or camera), so that it reuses between frames what did not change
//! (`volscatter_core::solvers::session`). Thin over `Session` and the GPU dispatch.

use std::ffi::{c_char, c_void};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, TryLockError};

use volscatter_core::pipeline::Session;
use volscatter_gpu::DeviceChoice;

use super::guard::{self, clear_out, on_handle, write_out};
use super::handle::lock;
use super::handle::Registry;
use super::progress::{in_callback, CProgress, VsProgressCallback};
use super::result::{ResultState, VsResult, RESULTS};
use super::scene::{VsScene, SCENES};
use super::status::{FfiError, VsStatus};

/// Opaque session handle. Create with `vs_session_new`, destroy with `vs_session_destroy`.
pub struct VsSession {
    _private: [u8; 0],
}

/// The handle's mutex is held only to clone this `Arc`, never through a solve: the count is
/// read without waiting, and a solve's own lock (`session`) is the one a frame waits on.
pub(crate) struct SessionState(Arc<Shared>);

struct Shared {
    session: Mutex<Session>,
    device: DeviceChoice,
    /// Calls of `vs_session_solve` on this session (failed and cancelled ones included, busy
    /// refusals not): atomic, so that a progress callback may read it mid-solve.
    frames: AtomicU64,
}

impl SessionState {
    fn shared(h: &super::handle::Handle<SessionState>) -> Arc<Shared> {
        Arc::clone(&lock(&h.state).0)
    }
}

pub(crate) static SESSIONS: Registry<SessionState, VsSession> = Registry::new("VsSession");

/// Creates a session in `*out` (NULL on failure; destroy with `vs_session_destroy`) with the
/// solver, settings and device of `scene` as they are now (`vs_scene_set_solver`,
/// `vs_scene_set_device`, or the scene JSON; default "reference"). They stay the session's for
/// its life; later changes to the scene's solver or device do not affect it. On failure the
/// message is on `scene` (`vs_scene_last_error`).
///
/// Thread safety: any thread.
#[no_mangle]
pub unsafe extern "C" fn vs_session_new(scene: *const VsScene, out: *mut *mut VsSession) -> VsStatus {
    let cleared = guard::call(|| clear_out(out, "out"));
    if cleared != VsStatus::Ok {
        return cleared;
    }
    on_handle(&SCENES, scene, |h| {
        let (scene, device) = {
            let st = lock(&h.state);
            (st.scene.clone(), st.device)
        };
        let session = Session::for_scene(&scene, volscatter_gpu::devices(device))?;
        let shared = Shared { session: Mutex::new(session), device, frames: AtomicU64::new(0) };
        write_out(out, SESSIONS.insert(SessionState(Arc::new(shared)))?, "out")
    })
}

/// Destroys a session and what it kept. NULL is ignored; a dead handle gives
/// `VS_STATUS_INVALID_HANDLE`. Results solved in it stay valid. A solve running on another
/// thread finishes normally.
///
/// Thread safety: any thread; the handle must not be used afterwards.
#[no_mangle]
pub unsafe extern "C" fn vs_session_destroy(session: *mut VsSession) -> VsStatus {
    guard::call(|| if session.is_null() { Ok(()) } else { SESSIONS.remove(session) })
}

/// The message of the last call on this session that failed, or "" if it succeeded; valid
/// until the next call on the session or its destruction. For a NULL or dead handle, a static
/// description.
///
/// Thread safety: meaningful only when no other thread calls functions on this session.
#[no_mangle]
pub unsafe extern "C" fn vs_session_last_error(session: *const VsSession) -> *const c_char {
    guard::value(VsStatus::Internal.description().as_ptr().cast(), || match SESSIONS.get(session) {
        Ok(h) => h.error.as_ptr(),
        Err(e) => e.status.description().as_ptr().cast(),
    })
}

/// Solves `scene` as it is now (medium, lights, camera: any of them may have changed since
/// the last frame) with the session's solver, reusing what earlier frames computed and still
/// applies, and puts the scattering grid in a new result `*out` (NULL on failure; destroy
/// with `vs_result_destroy`). The result equals what `vs_scene_solve` gives for the same scene
/// with the session's solver and device. `progress` and cancelling as for `vs_scene_solve`.
/// Errors (including the scene's: no medium, NULL or dead scene handle) are on the session.
///
/// Thread safety: any thread. Calls on one session are serialised (a frame waits for the one
/// before); the scene is not kept locked during the solve. Called from inside a progress
/// callback (of any solve) while this session is solving, it returns `VS_STATUS_BUSY` at once
/// instead of waiting for a solve that waits for the callback.
#[no_mangle]
pub unsafe extern "C" fn vs_session_solve(
    session: *mut VsSession,
    scene: *const VsScene,
    progress: VsProgressCallback,
    user: *mut c_void,
    out: *mut *mut VsResult,
) -> VsStatus {
    on_handle(&SESSIONS, session, |h| {
        let shared = SessionState::shared(h);
        let cleared = clear_out(out, "out");
        let mut st = match shared.session.try_lock() {
            Ok(st) => st,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) if in_callback() => {
                return Err(FfiError::new(VsStatus::Busy, "busy: this session is solving, and a progress callback cannot wait for the solve it reports on"));
            }
            Err(TryLockError::WouldBlock) => lock(&shared.session),
        };
        // Counted once it is this session's frame, before anything can fail.
        shared.frames.fetch_add(1, Ordering::SeqCst);
        cleared?;
        let snapshot = lock(&SCENES.get(scene)?.state).snapshot()?;
        let progress = CProgress::new(progress, user);
        let device = shared.device;
        let solved = progress.with_heartbeat(|| st.solve(&snapshot, &progress))?; // a GPU failure is Error::Device: VS_STATUS_DEVICE
        if progress.cancelled() {
            return Err(FfiError::new(VsStatus::Cancelled, "cancelled"));
        }
        let state = ResultState::new(solved, snapshot, device)?;
        write_out(out, RESULTS.insert(state)?, "out")
    })
}

/// Writes the number of solves run in this session so far to `*out`: every
/// `vs_session_solve` call on it, including the one running now and those that failed (bad
/// arguments, a scene without a medium) or were cancelled; not those refused with
/// `VS_STATUS_BUSY`.
///
/// Thread safety: any thread, a progress callback included; never waits for a solve.
#[no_mangle]
pub unsafe extern "C" fn vs_session_frame_count(session: *const VsSession, out: *mut u64) -> VsStatus {
    on_handle(&SESSIONS, session, |h| write_out(out, SessionState::shared(h).frames.load(Ordering::SeqCst), "out"))
}
