//! Opaque handles. A handle given to C is not a pointer to the object: it is a number drawn
//! from a counter that never repeats (within 2^60 handles on 64-bit), looked up in a registry
//! of live objects of its type on every call. So a destroyed handle, a handle destroyed twice,
//! a handle of another type or a made-up value is *detected* (`VS_STATUS_INVALID_HANDLE`)
//! instead of being dereferenced — stronger than a magic field, which reads freed memory.
//!
//! Limits: on 32-bit targets the counter has 2^28 values and then refuses new handles; a
//! handle value copied around by the host is still "live" until destroyed (as with any API).
//!
//! Each object sits behind its own mutex, so independent handles are used from several
//! threads at once, and calls on one handle from several threads are serialised.

use std::collections::BTreeMap;
use std::ffi::{c_char, CString};
use std::marker::PhantomData;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use super::status::{FfiError, FfiResult, VsStatus};

/// Locks, ignoring poisoning: a panic inside a call is caught by the guard and reported, and
/// the objects behind these locks are only ever replaced whole, so they stay consistent.
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The last error of a handle, as a C string whose pointer stays valid until replaced.
#[derive(Default)]
pub(crate) struct ErrorSlot(Mutex<CString>);

impl ErrorSlot {
    pub fn record(&self, outcome: &FfiResult) {
        let text = match outcome {
            Ok(()) => CString::default(),
            Err(e) => CString::new(e.message.replace('\0', " ")).unwrap_or_default(),
        };
        *lock(&self.0) = text;
    }
    pub fn as_ptr(&self) -> *const c_char {
        lock(&self.0).as_ptr()
    }
}

pub(crate) struct Handle<T> {
    pub state: Mutex<T>,
    pub error: ErrorSlot,
}

/// One registry per object type; `Opaque` is the C-side type name (`VsScene`, ...).
pub(crate) struct Registry<T, Opaque> {
    name: &'static str,
    live: Mutex<BTreeMap<usize, Arc<Handle<T>>>>,
    _opaque: PhantomData<fn() -> Opaque>,
}

static NEXT_HANDLE: AtomicUsize = AtomicUsize::new(1);

impl<T, Opaque> Registry<T, Opaque> {
    pub const fn new(name: &'static str) -> Self {
        Registry { name, live: Mutex::new(BTreeMap::new()), _opaque: PhantomData }
    }

    pub fn insert(&self, state: T) -> FfiResult<*mut Opaque> {
        let n = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed);
        if n >= usize::MAX >> 4 {
            return Err(FfiError::new(VsStatus::TooLarge, "handle numbers exhausted"));
        }
        // Multiples of 16 from 16 up: they look like aligned pointers to tools, are never NULL,
        // and never repeat.
        let id = n << 4;
        lock(&self.live).insert(id, Arc::new(Handle { state: Mutex::new(state), error: ErrorSlot::default() }));
        Ok(id as *mut Opaque)
    }

    pub fn get(&self, h: *const Opaque) -> FfiResult<Arc<Handle<T>>> {
        if h.is_null() {
            return Err(FfiError::null(&format!("the {} handle", self.name)));
        }
        lock(&self.live).get(&(h as usize)).cloned().ok_or_else(|| self.invalid(h))
    }

    /// Removes the handle; the object is freed when the last call using it returns.
    pub fn remove(&self, h: *const Opaque) -> FfiResult {
        match lock(&self.live).remove(&(h as usize)) {
            Some(_) => Ok(()),
            None => Err(self.invalid(h)),
        }
    }

    fn invalid(&self, h: *const Opaque) -> FfiError {
        FfiError::new(
            VsStatus::InvalidHandle,
            format!("{h:p} is not a live {} handle (destroyed, never created, or of another type)", self.name),
        )
    }

    #[cfg(test)]
    pub fn live_count(&self) -> usize {
        lock(&self.live).len()
    }
}
