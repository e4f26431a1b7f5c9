//! Host-side packing of core types into GPU buffers.

use glam::{Affine3A, IVec3, Vec3};
use volscatter_core::medium::Medium;
use volscatter_core::ScatteringGrid;

/// A 3x4 affine as three rows (WGSL `array<vec4<f32>, 3>`).
pub fn affine_rows(a: &Affine3A) -> [[f32; 4]; 3] {
    let m = glam::Mat4::from(*a);
    [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array()]
}

/// The medium's density as a dense x-fastest array over its index bounds plus the one-voxel
/// zero ring (so the kernel's trilinear lookups match `DensityGrid::sample` everywhere).
/// Returns (index of element 0, dims, values).
pub fn dense_density(medium: &Medium) -> (IVec3, IVec3, Vec<f32>) {
    if medium.grid.is_empty() {
        return (IVec3::ZERO, IVec3::ONE, vec![0.0]);
    }
    let (lo, hi) = medium.grid.bbox();
    let origin = lo - IVec3::ONE;
    let dims = hi - lo + IVec3::splat(3);
    let mut values = Vec::with_capacity(dims.x as usize * dims.y as usize * dims.z as usize);
    for z in 0..dims.z {
        for y in 0..dims.y {
            for x in 0..dims.x {
                values.push(medium.grid.voxel(origin + IVec3::new(x, y, z)));
            }
        }
    }
    (origin, dims, values)
}

/// Bytes the dense density would take, to check limits before building it.
pub fn dense_density_bytes(medium: &Medium) -> u64 {
    let (lo, hi) = medium.grid.bbox();
    let d = (hi - lo + IVec3::splat(3)).max(IVec3::ONE).as_i64vec3();
    (d.x * d.y * d.z) as u64 * 4
}

/// RGB grid as vec4 (WGSL arrays of vec3 have a 16-byte stride anyway).
pub fn rgb_as_vec4(data: &[Vec3]) -> Vec<[f32; 4]> {
    data.iter().map(|v| [v.x, v.y, v.z, 0.0]).collect()
}

pub fn grid_dims(g: &ScatteringGrid) -> [u32; 4] {
    [g.dims[0], g.dims[1], g.dims[2], 0]
}
