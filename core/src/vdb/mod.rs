//! OpenVDB reader and writer (issue 2/9). Placeholder until it lands.

use glam::Affine3A;
use std::path::Path;

use crate::error::{Error, Result};
use crate::medium::{DensityGrid, GridLimits};

/// Loads a float grid (by name, or the first float grid) into a density grid, with its
/// index-to-object map.
pub fn load_density(path: &Path, _grid: Option<&str>, _limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    Err(Error::format(path, "VDB reading is not implemented yet"))
}
