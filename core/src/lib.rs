//! volscatter-core: scene model, VDB and EXR I/O, phase functions, solvers, reference path
//! tracer and compositor. Pure CPU; no FFI (that is `plugin/`).

pub mod budget;
pub mod compositor;
pub mod error;
pub mod image;
pub mod io;
pub mod lattice_product;
pub mod medium;
pub mod phase;
pub mod pipeline;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod solvers;
pub mod stages;
pub mod translate;
pub mod vdb;

pub use error::{Error, Result};
pub use image::Image;
pub use medium::Medium;
pub use scene::Scene;
pub use solvers::{SolveOutput, Solver};
pub use stages::{Progress, ScatteringGrid};

pub const VERSION: &str = env!("CARGO_PKG_VERSION");
