//! The scattering grid as an OpenEXR image of stacked z slices (see `VsGridFormat::Exr`).

use std::path::Path;

use exr::prelude::*;
use volscatter_core::stages::ScatteringGrid;

use super::status::{FfiError, FfiResult, VsStatus};

pub(crate) fn write_grid(path: &Path, grid: &ScatteringGrid) -> FfiResult {
    let [nx, ny, nz] = grid.dims.map(|d| d as usize);
    let height = ny.checked_mul(nz).filter(|&h| h <= i32::MAX as usize && nx <= i32::MAX as usize);
    let Some(height) = height else {
        return Err(FfiError::new(VsStatus::TooLarge, format!("grid {nx}x{ny}x{nz} is too large for one EXR image")));
    };
    // Grid index (i, j, k) -> pixel (i, k * ny + j): that is the grid's own x-fastest order.
    let channel = |name: &str, c: usize| AnyChannel::new(name, FlatSamples::F32(grid.data.iter().map(|v| v[c]).collect()));
    let channels = AnyChannels::sort(vec![channel("R", 0), channel("G", 1), channel("B", 2)].into());
    let mut attributes = LayerAttributes::named("scattering");
    attributes.other.insert(Text::from("volscatterDims"), AttributeValue::Text(Text::from(format!("{nx} {ny} {nz}").as_str())));
    let m = glam::Mat4::from(grid.index_to_world).transpose().to_cols_array();
    attributes.other.insert(Text::from("volscatterIndexToWorld"), AttributeValue::Matrix4x4(m));
    let layer = Layer::new((nx, height), attributes, Encoding::SMALL_LOSSLESS, channels);
    // Encoded in memory and written checked: a full disk or a missing folder is VS_STATUS_IO.
    volscatter_core::io::exr::write_layer(path, layer)?;
    Ok(())
}
