//! The status every export returns, and the error type the C layer carries until it becomes a
//! status plus a message stored on the handle.

use std::ffi::{c_char, CStr};

use volscatter_core::Error;

/// Outcome of a call. `VS_STATUS_OK` is 0; every other value is a failure whose message is
/// available from the handle's `vs_*_last_error` (or, for calls without a handle, from
/// `vs_status_message`). New values may be added in later versions with the same ABI version:
/// treat unknown values as errors.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VsStatus {
    /// Success.
    Ok = 0,
    /// A required pointer argument was NULL.
    NullArgument = 1,
    /// An argument is out of range, not finite, not UTF-8, or an unknown enum value or flag.
    InvalidArgument = 2,
    /// The handle is not a live object of the expected type: destroyed, never created, or a
    /// handle of another type.
    InvalidHandle = 3,
    /// A caller buffer's length does not match what the call needs (or is misaligned).
    BufferSize = 4,
    /// The scene description is invalid (the message names the field), or the scene is not
    /// complete enough for the call (no medium, no camera).
    InvalidScene = 5,
    /// A file could not be read or written.
    Io = 6,
    /// A file exists but cannot be decoded.
    Format = 7,
    /// The request would need more memory than allowed; refused before allocating.
    TooLarge = 8,
    /// The operation is not supported by this build.
    Unsupported = 9,
    /// The progress callback asked to stop.
    Cancelled = 10,
    /// A bug in volscatter (a caught panic). The handle stays usable; please report the message.
    Internal = 11,
    /// The GPU asked for with `VS_DEVICE_GPU` failed: no adapter, a device request refused, out
    /// of device memory, a lost device. Under `VS_DEVICE_AUTO` such failures run on the CPU
    /// instead and are not reported. Retrying with `VS_DEVICE_CPU` works.
    Device = 12,
    /// The session is solving, and the call came from a progress callback, which cannot wait
    /// for the solve it reports on. Call again after that solve returns.
    Busy = 13,
}

impl VsStatus {
    pub(crate) const ALL: [VsStatus; 14] = [
        VsStatus::Ok,
        VsStatus::NullArgument,
        VsStatus::InvalidArgument,
        VsStatus::InvalidHandle,
        VsStatus::BufferSize,
        VsStatus::InvalidScene,
        VsStatus::Io,
        VsStatus::Format,
        VsStatus::TooLarge,
        VsStatus::Unsupported,
        VsStatus::Cancelled,
        VsStatus::Internal,
        VsStatus::Device,
        VsStatus::Busy,
    ];

    /// Converts a C integer, never by transmute: unknown values give `None`.
    pub(crate) fn from_i32(v: i32) -> Option<VsStatus> {
        VsStatus::ALL.iter().copied().find(|s| *s as i32 == v)
    }

    /// A static, NUL-terminated description of the status.
    pub(crate) fn description(self) -> &'static CStr {
        match self {
            VsStatus::Ok => c"ok",
            VsStatus::NullArgument => c"a required pointer argument was NULL",
            VsStatus::InvalidArgument => c"invalid argument",
            VsStatus::InvalidHandle => c"invalid handle (destroyed, never created, or of another type)",
            VsStatus::BufferSize => c"buffer length does not match",
            VsStatus::InvalidScene => c"invalid or incomplete scene",
            VsStatus::Io => c"file could not be read or written",
            VsStatus::Format => c"file could not be decoded",
            VsStatus::TooLarge => c"request too large",
            VsStatus::Unsupported => c"not supported by this build",
            VsStatus::Cancelled => c"cancelled",
            VsStatus::Internal => c"internal error",
            VsStatus::Device => c"the GPU device failed (no adapter, out of memory, or lost)",
            VsStatus::Busy => c"busy: the session is solving (called from its progress callback)",
        }
    }
}

/// A failed call: the status to return and the message to store on the handle.
#[derive(Debug, Clone)]
pub(crate) struct FfiError {
    pub status: VsStatus,
    pub message: String,
}

pub(crate) type FfiResult<T = ()> = Result<T, FfiError>;

impl FfiError {
    pub fn new(status: VsStatus, message: impl Into<String>) -> Self {
        FfiError { status, message: message.into() }
    }
    pub fn null(what: &str) -> Self {
        FfiError::new(VsStatus::NullArgument, format!("{what} is NULL"))
    }
    pub fn invalid(message: impl Into<String>) -> Self {
        FfiError::new(VsStatus::InvalidArgument, message)
    }
    pub fn buffer(message: impl Into<String>) -> Self {
        FfiError::new(VsStatus::BufferSize, message)
    }
    pub fn scene(message: impl Into<String>) -> Self {
        FfiError::new(VsStatus::InvalidScene, message)
    }
}

impl From<Error> for FfiError {
    fn from(e: Error) -> Self {
        let status = match &e {
            Error::Scene { .. } => VsStatus::InvalidScene,
            Error::Io { .. } => VsStatus::Io,
            Error::Format { .. } => VsStatus::Format,
            Error::Unsupported { .. } => VsStatus::Unsupported,
            Error::TooLarge(_) => VsStatus::TooLarge,
            Error::InvalidArgument(_) => VsStatus::InvalidArgument,
            Error::Cancelled => VsStatus::Cancelled,
            Error::Device(_) => VsStatus::Device,
        };
        FfiError { status, message: e.to_string() }
    }
}

/// A static description of a status code, for failures that have no handle to carry a message
/// (a NULL or destroyed handle). Unknown values give "unknown status". Never NULL; the string
/// lives as long as the library is loaded.
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub extern "C" fn vs_status_message(status: i32) -> *const c_char {
    super::guard::value(c"internal error".as_ptr().cast(), || match VsStatus::from_i32(status) {
        Some(s) => s.description().as_ptr().cast(),
        None => c"unknown status".as_ptr().cast(),
    })
}
