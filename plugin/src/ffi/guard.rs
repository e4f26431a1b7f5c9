//! The one wrapper every export runs through, and the argument checks it offers.
//!
//! `protect` is the single `catch_unwind`: no panic leaves the library (an `extern "C"`
//! function that unwinds aborts the host). On top of it, `call` runs a body that returns a
//! status, and `on_handle` looks a handle up first and stores the body's error message on it.
//! Argument helpers check NULL pointers, UTF-8, finiteness, lengths and alignment before any
//! slice is formed or memory allocated.

use std::any::Any;
use std::cell::RefCell;
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Once};

use super::handle::{Handle, Registry};
use super::status::{FfiError, FfiResult, VsStatus};

fn panic_message(payload: &(dyn Any + Send)) -> String {
    let what = if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_string()
    };
    // Where it happened, when the panic was on this thread (a worker thread's panic is
    // re-raised here with its message; its location stayed on the worker).
    let at = PANIC_LOCATION.with(|l| l.borrow_mut().take()).map(|l| format!(" at {l}")).unwrap_or_default();
    format!("internal error (please report): {what}{at}")
}

/// Exports running now, on any thread. While one runs, a panic anywhere in the library (its
/// own thread or a rayon worker of its solve) is the export's to report: the host's stderr
/// gets nothing (a Blender console full of Rust backtraces for an error the add-on already
/// shows). Outside exports (the CLI, Rust hosts of the rlib) the previous hook runs as before.
static IN_EXPORT: AtomicUsize = AtomicUsize::new(0);
static QUIET_HOOK: Once = Once::new();

thread_local! {
    /// The location of the last panic on this thread inside an export, for its message.
    static PANIC_LOCATION: RefCell<Option<String>> = const { RefCell::new(None) };
}

fn install_quiet_hook() {
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_EXPORT.load(Ordering::SeqCst) == 0 {
                return previous(info);
            }
            let at = info.location().map(|l| format!("{}:{}", l.file(), l.line()));
            // try_with: a panic while this thread's locals are being torn down records nothing.
            let _ = PANIC_LOCATION.try_with(|slot| {
                if let Ok(mut slot) = slot.try_borrow_mut() {
                    *slot = at;
                }
            });
        }));
    });
}

/// Counts one export in flight for as long as it lives (a drop, so a panic still uncounts).
struct InExport;
impl InExport {
    fn enter() -> Self {
        install_quiet_hook();
        IN_EXPORT.fetch_add(1, Ordering::SeqCst);
        InExport
    }
}
impl Drop for InExport {
    fn drop(&mut self) {
        IN_EXPORT.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Runs `body`; a panic becomes `on_panic(message)`. Nothing is printed (`install_quiet_hook`).
pub(crate) fn protect<T>(body: impl FnOnce() -> T, on_panic: impl FnOnce(String) -> T) -> T {
    let _in_export = InExport::enter();
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(v) => v,
        Err(payload) => {
            // Dropping a payload can itself panic; never let that escape either.
            let msg = catch_unwind(AssertUnwindSafe(|| panic_message(&*payload))).unwrap_or_else(|_| "internal error".into());
            if catch_unwind(AssertUnwindSafe(move || drop(payload))).is_err() {
                // The payload of the payload is leaked: nothing better to do.
            }
            on_panic(msg)
        }
    }
}

/// For exports that return a value rather than a status (version strings, messages).
pub(crate) fn value<T>(fallback: T, body: impl FnOnce() -> T) -> T {
    protect(body, |_| fallback)
}

/// For exports without a handle (or that create one): the status of `body`, panics included.
pub(crate) fn call(body: impl FnOnce() -> FfiResult) -> VsStatus {
    match protect(body, |m| Err(FfiError::new(VsStatus::Internal, m))) {
        Ok(()) => VsStatus::Ok,
        Err(e) => e.status,
    }
}

/// For exports on a handle: looks it up (NULL and dead handles are refused), runs `body`, and
/// records the outcome as the handle's last error ("" on success).
pub(crate) fn on_handle<T, O>(registry: &Registry<T, O>, h: *const O, body: impl FnOnce(&Arc<Handle<T>>) -> FfiResult) -> VsStatus {
    protect(
        || {
            let handle = match registry.get(h) {
                Ok(handle) => handle,
                Err(e) => return e.status,
            };
            let outcome = protect(|| body(&handle), |m| Err(FfiError::new(VsStatus::Internal, m)));
            handle.error.record(&outcome);
            match outcome {
                Ok(()) => VsStatus::Ok,
                Err(e) => e.status,
            }
        },
        |_| VsStatus::Internal,
    )
}

// ---- argument checks ---------------------------------------------------------------------

/// A NUL-terminated UTF-8 string argument.
pub(crate) unsafe fn str_arg<'a>(p: *const c_char, what: &str) -> FfiResult<&'a str> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    CStr::from_ptr(p).to_str().map_err(|e| FfiError::invalid(format!("{what} is not valid UTF-8: {e}")))
}

/// An optional string: NULL gives `None`.
pub(crate) unsafe fn opt_str_arg<'a>(p: *const c_char, what: &str) -> FfiResult<Option<&'a str>> {
    if p.is_null() {
        Ok(None)
    } else {
        str_arg(p, what).map(Some)
    }
}

/// A file path (bytes on Unix, UTF-8 elsewhere); must not be empty.
pub(crate) unsafe fn path_arg(p: *const c_char, what: &str) -> FfiResult<PathBuf> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    let bytes = CStr::from_ptr(p).to_bytes();
    if bytes.is_empty() {
        return Err(FfiError::invalid(format!("{what} is empty")));
    }
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(PathBuf::from(std::ffi::OsStr::from_bytes(bytes)))
    }
    #[cfg(not(unix))]
    {
        Ok(PathBuf::from(std::str::from_utf8(bytes).map_err(|e| FfiError::invalid(format!("{what} is not valid UTF-8: {e}")))?))
    }
}

/// A path that must name an existing regular file of at most `max_bytes` (so that reading it
/// whole cannot exhaust memory: `/dev/zero` and FIFOs are refused).
pub(crate) unsafe fn input_file_arg(p: *const c_char, what: &str, max_bytes: u64) -> FfiResult<PathBuf> {
    let path = path_arg(p, what)?;
    let meta = std::fs::metadata(&path).map_err(|e| FfiError::new(VsStatus::Io, format!("{}: {e}", path.display())))?;
    if !meta.is_file() {
        return Err(FfiError::new(VsStatus::Io, format!("{}: not a regular file", path.display())));
    }
    if meta.len() > max_bytes {
        return Err(FfiError::new(
            VsStatus::TooLarge,
            format!("{}: {} MiB is over the limit of {} MiB", path.display(), meta.len() >> 20, max_bytes >> 20),
        ));
    }
    Ok(path)
}

/// `N` floats read from `p`, each finite.
pub(crate) unsafe fn floats_arg<const N: usize>(p: *const f32, what: &str) -> FfiResult<[f32; N]> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    let mut out = [0.0f32; N];
    for (i, v) in out.iter_mut().enumerate() {
        // Unaligned reads: a host may pass floats packed in a byte buffer.
        *v = p.add(i).read_unaligned();
        if !v.is_finite() {
            return Err(FfiError::invalid(format!("{what}[{i}] is {v}: must be finite")));
        }
    }
    Ok(out)
}

pub(crate) fn finite_arg(v: f32, what: &str) -> FfiResult<f32> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(FfiError::invalid(format!("{what} is {v}: must be finite")))
    }
}

/// A caller buffer of exactly `needed` elements, checked for NULL, length and alignment.
pub(crate) unsafe fn out_slice<'a, T>(p: *mut T, len: usize, needed: usize, what: &str) -> FfiResult<&'a mut [T]> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    if len != needed {
        return Err(FfiError::buffer(format!("{what} holds {len} values; this call needs exactly {needed}")));
    }
    if !p.is_aligned() {
        return Err(FfiError::buffer(format!("{what} at {p:p} is not aligned to {} bytes", std::mem::align_of::<T>())));
    }
    if needed.checked_mul(std::mem::size_of::<T>()).is_none_or(|b| b > isize::MAX as usize) {
        return Err(FfiError::new(VsStatus::TooLarge, format!("{what}: {needed} values is too large")));
    }
    Ok(std::slice::from_raw_parts_mut(p, len))
}

/// A caller input buffer of `len` elements (len > 0), checked for NULL and alignment.
pub(crate) unsafe fn in_slice<'a, T>(p: *const T, len: usize, what: &str) -> FfiResult<&'a [T]> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    if len == 0 {
        return Err(FfiError::buffer(format!("{what} is empty (length 0)")));
    }
    if !p.is_aligned() {
        return Err(FfiError::buffer(format!("{what} at {p:p} is not aligned to {} bytes", std::mem::align_of::<T>())));
    }
    if len.checked_mul(std::mem::size_of::<T>()).is_none_or(|b| b > isize::MAX as usize) {
        return Err(FfiError::new(VsStatus::TooLarge, format!("{what}: length {len} is too large")));
    }
    Ok(std::slice::from_raw_parts(p, len))
}

/// Writes `*out = value` after checking `out` for NULL.
pub(crate) unsafe fn write_out<T>(out: *mut T, value: T, what: &str) -> FfiResult {
    if out.is_null() {
        return Err(FfiError::null(what));
    }
    out.write_unaligned(value);
    Ok(())
}

/// Clears an output handle pointer first thing, so that it is NULL on every failure.
pub(crate) unsafe fn clear_out<T>(out: *mut *mut T, what: &str) -> FfiResult {
    if out.is_null() {
        return Err(FfiError::null(what));
    }
    out.write_unaligned(std::ptr::null_mut());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::handle::Registry;
    use super::*;

    struct Opaque;

    #[test]
    fn a_panic_becomes_an_internal_status_with_its_message_on_the_handle() {
        static REG: Registry<u32, Opaque> = Registry::new("Test");
        let h = REG.insert(7).unwrap();
        let st = on_handle(&REG, h, |_| panic!("boom {}", 42));
        assert_eq!(st, VsStatus::Internal);
        let handle = REG.get(h).unwrap();
        let msg = unsafe { CStr::from_ptr(handle.error.as_ptr()) }.to_str().unwrap().to_string();
        assert!(msg.contains("boom 42") && msg.contains("internal error"), "{msg}");
        assert!(msg.contains("guard.rs:"), "the message says where: {msg}");
        // A panic while the state is locked poisons the mutex; the handle stays usable.
        let st = on_handle(&REG, h, |hd| {
            let _g = hd.state.lock();
            panic!("while locked")
        });
        assert_eq!(st, VsStatus::Internal);
        assert_eq!(on_handle(&REG, h, |hd| { *super::super::handle::lock(&hd.state) += 1; Ok(()) }), VsStatus::Ok);
        assert_eq!(*super::super::handle::lock(&REG.get(h).unwrap().state), 8);
        assert_eq!(unsafe { CStr::from_ptr(REG.get(h).unwrap().error.as_ptr()) }.to_bytes(), b"", "success clears");
        assert_eq!(call(|| panic!("no handle")), VsStatus::Internal);
        assert_eq!(value(5, || panic!("value")), 5);
        REG.remove(h).unwrap();
        assert_eq!(REG.live_count(), 0);
        assert_eq!(on_handle(&REG, h, |_| Ok(())), VsStatus::InvalidHandle);
        assert_eq!(on_handle(&REG, std::ptr::null(), |_| Ok(())), VsStatus::NullArgument);
    }

    /// Run as a child by the test below: panics inside an export (on its own thread and on a
    /// rayon worker) and outside one, then exits.
    #[test]
    fn panic_child() {
        if std::env::var_os("VS_PANIC_CHILD").is_none() {
            return; // only meaningful as the child of the test below
        }
        assert_eq!(call(|| panic!("own thread")), VsStatus::Internal);
        let st = call(|| {
            // As rayon does: the worker's panic is re-raised on the calling thread.
            if let Err(payload) = std::thread::spawn(|| panic!("worker thread")).join() {
                std::panic::resume_unwind(payload);
            }
            Ok(())
        });
        assert_eq!(st, VsStatus::Internal);
        eprintln!("CHILD-DONE");
        let _ = std::panic::catch_unwind(|| panic!("outside any export"));
    }

    /// A panic caught inside an export prints nothing to the host's stderr (its message goes to
    /// the error instead); outside exports the default hook still prints.
    #[test]
    fn panics_inside_exports_print_nothing() {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["ffi::guard::tests::panic_child", "--exact", "--nocapture", "--test-threads=1"])
            .env("VS_PANIC_CHILD", "1")
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "child failed: {stderr}");
        assert!(stderr.contains("CHILD-DONE"), "the child ran: {stderr}");
        let inside = stderr.split("CHILD-DONE").next().unwrap_or_default();
        assert!(!inside.contains("own thread") && !inside.contains("worker thread") && !inside.contains("backtrace"), "printed: {stderr}");
        assert!(stderr.contains("outside any export"), "the previous hook still runs outside exports: {stderr}");
    }

    #[test]
    fn buffers_are_checked_before_use() {
        let mut v = [0f32; 4];
        unsafe {
            assert_eq!(out_slice(v.as_mut_ptr(), 4, 4, "v").unwrap().len(), 4);
            assert_eq!(out_slice(v.as_mut_ptr(), 3, 4, "v").unwrap_err().status, VsStatus::BufferSize);
            assert_eq!(out_slice::<f32>(std::ptr::null_mut(), 4, 4, "v").unwrap_err().status, VsStatus::NullArgument);
            let odd = (v.as_mut_ptr() as *mut u8).add(1) as *mut f32;
            assert_eq!(out_slice(odd, 2, 2, "v").unwrap_err().status, VsStatus::BufferSize);
            assert_eq!(in_slice(v.as_ptr(), usize::MAX / 2, "v").unwrap_err().status, VsStatus::TooLarge);
            assert_eq!(in_slice(v.as_ptr(), 0, "v").unwrap_err().status, VsStatus::BufferSize);
            let nan = [1.0f32, f32::NAN, 0.0];
            let e = floats_arg::<3>(nan.as_ptr(), "x").unwrap_err();
            assert!(e.message.contains("x[1]"), "{}", e.message);
            assert_eq!(input_file_arg(c"/dev/zero".as_ptr(), "p", 1 << 20).unwrap_err().status, VsStatus::Io);
        }
    }
}
