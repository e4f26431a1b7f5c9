//! Raw little-endian float32 density files (x fastest, then y, then z): the simplest way for a
//! script (numpy's `tofile`) to hand a dense grid to volscatter, used by the cross-renderer tests.

use glam::IVec3;
use std::path::Path;

use super::{DensityGrid, GridLimits};
use crate::error::{Error, Result};

pub fn read_raw_f32(path: &Path, dims: [u32; 3], limits: GridLimits) -> Result<DensityGrid> {
    let count = dims.iter().map(|&d| d as u64).product::<u64>();
    if dims.contains(&0) {
        return Err(Error::format(path, "raw grid dimensions must be positive"));
    }
    if count * 4 > limits.max_bytes || count > limits.max_extent_voxels {
        return Err(Error::TooLarge(format!("raw grid {}x{}x{} is over the memory limit", dims[0], dims[1], dims[2])));
    }
    let len = crate::io::files::regular_file(path, "raw density file")?;
    if len != count * 4 {
        return Err(Error::format(
            path,
            format!("is {len} bytes, but {}x{}x{} float32 values need {}", dims[0], dims[1], dims[2], count * 4),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let values: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let d = IVec3::new(dims[0] as i32, dims[1] as i32, dims[2] as i32);
    DensityGrid::from_dense(IVec3::ZERO, d, &values, limits).map_err(|e| match e {
        Error::InvalidArgument(m) => Error::format(path, m),
        other => other,
    })
}
