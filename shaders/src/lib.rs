//! volscatter-gpu: WGSL compute kernels and the wgpu code that dispatches them. Same inputs and
//! outputs as the CPU code in volscatter-core, compared against it in tests on any adapter
//! (Mesa's lavapipe on GPU-less machines).
//!
//! Every kernel lives in a folder of its own: its WGSL, the Rust that uploads inputs, records
//! the dispatch and reads results back, the `#[repr(C)]` parameter struct whose layout is
//! checked against the WGSL at compile time (size/offset asserts) and by naga in a unit test.
//!
//! Nothing here panics into the caller: wgpu's uncaptured-error handler is replaced, errors are
//! caught with error scopes, and a lost device or out-of-memory becomes a `GpuError`, on which
//! callers fall back to the CPU.

pub mod backends;
pub mod composite;
pub mod context;
pub mod device;
pub mod lpm;
pub mod network;
pub mod photon_grid;
pub mod pop;
pub mod upload;
pub mod vpl;
mod wgsl;

#[cfg(test)]
mod session_counters_tests;
#[cfg(test)]
mod test_support;

pub use context::{GpuContext, GpuError};
pub use backends::{devices, Gpu, GPU};
pub use device::{DeviceChoice, DeviceUsed};
