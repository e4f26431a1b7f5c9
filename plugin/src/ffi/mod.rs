//! The C ABI (DESIGN.md "Engineering rules", issue 4/9). Thin: every export checks its
//! arguments, calls the public Rust API of `volscatter-core`, and turns the outcome into a
//! `VsStatus` plus a message stored on the handle. All exports run through `guard`.
//!
//! The header `plugin/include/volscatter.h` is generated from these files by cbindgen
//! (`plugin/cbindgen.toml`); the doc comments here are the header's documentation.
#![allow(clippy::missing_safety_doc)] // the safety contract of every export is in the header

// In header order: cbindgen emits items in the order it meets them.
pub mod version;
pub mod status;
pub mod budget;
pub mod progress;
pub mod scene;
pub mod result;
pub mod session;
pub mod image;
// The solver registry (issue 14).
pub mod solvers;
pub mod vdb_io;
pub mod guard;
mod grid_exr;
mod handle;

pub use image::VsImage;
pub use progress::VsProgressCallback;
pub use result::{VsGridFormat, VsResult};
pub use scene::VsScene;
pub use session::VsSession;
pub use status::VsStatus;
pub use version::{VS_ABI_VERSION, VS_COMPOSITE_TRANSPARENT};
