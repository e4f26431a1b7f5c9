//! The procedural cumulus of the dense-cloud fixture (solvers/fixtures/cloud.json): overlapping
//! ellipsoidal lumps above a flat base, with noise-eroded edges, filling the box [-1, 1]^3
//! metres. Clouds are what papers 01 and 04 are about and no other built-in medium is one: a
//! dense interior (density 1 over most of the core, so `density_scale` sets the optical depth
//! directly) where light scatters hundreds of times, a sharp flat underside that lies in the
//! cloud's own shadow, and a bumpy lit top. Deterministic (hash noise, no RNG state).

use glam::{Affine3A, IVec3, Vec3};

use super::procedural::{fbm, on_cube, smoothstep};
use super::{DensityGrid, GridLimits};
use crate::error::Result;

/// Height of the flat base (m): cumulus tops billow, their bases sit at the condensation level.
pub const BASE_Z: f32 = -0.5;

/// (centre, semi-axes) of the lumps, in metres: one wide body on the base and towers above it,
/// off-centre so the silhouette is not symmetric about any axis.
const LUMPS: [(Vec3, Vec3); 6] = [
    (Vec3::new(0.0, 0.0, -0.35), Vec3::new(0.8, 0.6, 0.5)),
    (Vec3::new(-0.38, 0.08, 0.05), Vec3::new(0.42, 0.4, 0.42)),
    (Vec3::new(0.3, -0.08, 0.12), Vec3::new(0.45, 0.4, 0.48)),
    (Vec3::new(0.02, 0.12, 0.45), Vec3::new(0.36, 0.33, 0.36)),
    (Vec3::new(0.66, 0.18, -0.22), Vec3::new(0.28, 0.3, 0.28)),
    (Vec3::new(-0.68, -0.16, -0.28), Vec3::new(0.28, 0.28, 0.24)),
];

/// Cumulus density at a point of [-1, 1]^3: 1 in the core, falling to 0 over an eroded rim of
/// about 0.1 m, cut flat at `BASE_Z`.
pub fn cumulus_density(p: Vec3) -> f32 {
    // Inside-ness of the union of lumps: 1 at a lump's centre, 0 on its surface.
    let inside = LUMPS.iter().map(|(c, r)| 1.0 - ((p - *c) / *r).length()).fold(f32::MIN, f32::max);
    if inside < -0.3 {
        return 0.0;
    }
    // Erosion: noise of ~0.15 m features moves the surface in and out by up to ~0.1 of a lump's
    // radius (cauliflower edges), the finer octaves only matter near the surface.
    let eroded = inside + 0.35 * (fbm(p * 5.0 + Vec3::new(3.1, -1.7, 0.4)) - 0.5);
    let base = smoothstep(BASE_Z, BASE_Z + 0.04, p.z);
    smoothstep(0.0, 0.12, eroded) * base
}

/// The cumulus on an `n`^3 voxel grid and the index-to-world map placing it in [-1, 1]^3.
pub fn cumulus(n: u32, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    on_cube(n, limits, cumulus_density)
}

/// The cumulus on a `dims` lattice over [-1, 1]^3 (voxel centres), with its index-to-world
/// map: paper 04's 48 x 62 x 90 cloud for photon-grid's CPU and GPU benchmarks.
pub fn cumulus_on_lattice(dims: IVec3, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    let mut vals = Vec::with_capacity((dims.x.max(0) * dims.y.max(0) * dims.z.max(0)) as usize);
    for k in 0..dims.z {
        for j in 0..dims.y {
            for i in 0..dims.x {
                let p = (Vec3::new(i as f32, j as f32, k as f32) + 0.5) / dims.as_vec3() * 2.0 - 1.0;
                vals.push(cumulus_density(p));
            }
        }
    }
    let grid = DensityGrid::from_dense(IVec3::ZERO, dims, &vals, limits)?;
    let voxel = Vec3::splat(2.0) / dims.as_vec3();
    let to_world = Affine3A::from_translation(Vec3::splat(-1.0) + 0.5 * voxel) * Affine3A::from_scale(voxel);
    Ok((grid, to_world))
}
