//! What several solvers share, below every solver and the compositor: the scattering grid
//! they return, progress and timings, exact single scattering, the density mip and a grid's
//! footprint, upsampling from a coarse grid, the octahedral map of directions. Nothing here
//! names a solver, the registry or the compositor (scripts/import_graph.py checks).

pub mod counters;
pub mod diff;
pub mod grid;
pub mod mip;
pub mod octahedral;
pub mod progress;
pub mod single_scattering;
pub mod upsample;

pub use counters::Counters;
pub use diff::SceneDiff;
pub use grid::{ScatteringGrid, MAX_SCATTERING_GRID_POINTS};
pub use progress::{CancelOnly, NoProgress, Progress, Timings};
