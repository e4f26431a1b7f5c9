//! libvolscatter: the C ABI of volscatter (issue 4/9), over the Rust API of `volscatter-core`.
//! See `ffi` and the generated header `plugin/include/volscatter.h`.

// The ABI catches every panic at its boundary; with panic=abort a bug would kill the host.
#[cfg(panic = "abort")]
compile_error!("libvolscatter must be built with panic=unwind: the C ABI catches panics at its boundary");

pub mod ffi;

/// Library version, as in Cargo.toml.
pub const VERSION: &str = volscatter_core::VERSION;
