//! The procedural smoke plume of the embedded default scene: a rising, widening column with
//! fractal value-noise billows, filling the box [-1, 1]^3 metres. Deterministic (no RNG state).

use glam::{Affine3A, IVec3, Vec3};

use super::{DensityGrid, GridLimits};
use crate::error::Result;

fn hash(i: IVec3) -> f32 {
    let mut h = (i.x as u32).wrapping_mul(0x8da6_b343) ^ (i.y as u32).wrapping_mul(0xd816_3841) ^ (i.z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xff_ffff) as f32 / 0x100_0000 as f32
}

fn value_noise(p: Vec3) -> f32 {
    let f = p.floor();
    let i = f.as_ivec3();
    let t = p - f;
    let s = t * t * (Vec3::splat(3.0) - 2.0 * t);
    let mut acc = 0.0;
    for k in 0..8 {
        let o = IVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        let w = Vec3::select(o.cmpeq(IVec3::ONE), s, Vec3::ONE - s);
        acc += hash(i + o) * w.x * w.y * w.z;
    }
    acc
}

/// Fractal value noise in [0, 1]; shared with the cumulus (cumulus.rs).
pub(crate) fn fbm(p: Vec3) -> f32 {
    let (mut a, mut f, mut sum, mut norm) = (1.0, 1.0, 0.0, 0.0);
    for _ in 0..4 {
        sum += a * value_noise(p * f);
        norm += a;
        a *= 0.5;
        f *= 2.03;
    }
    sum / norm
}

pub(crate) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Plume density at a point of [-1, 1]^3 (peak values around 1).
pub fn plume_density(p: Vec3) -> f32 {
    let h = (p.z + 1.0) * 0.5;
    let centre = glam::Vec2::new(0.15 * (3.0 * h).sin(), 0.1 * (2.3 * h).cos());
    let radius = 0.3 + 0.5 * h;
    let r = (p.truncate() - centre).length() / radius;
    let envelope = (-2.5 * r * r).exp() * smoothstep(0.0, 0.12, h) * (1.0 - smoothstep(0.8, 1.0, h));
    let billow = fbm(p * 3.0 + Vec3::new(0.0, 0.0, -1.7 * h));
    (envelope * (0.35 + 1.3 * billow) - 0.1).max(0.0) * 1.4
}

/// The plume on an `n`^3 voxel grid and the index-to-world map placing it in [-1, 1]^3.
pub fn plume(n: u32, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    on_cube(n, limits, plume_density)
}

/// `density` sampled at the voxel centres of an `n`^3 grid over [-1, 1]^3 (shared by the
/// built-in media: plume, cumulus), and the index-to-world map placing it there.
pub(crate) fn on_cube(n: u32, limits: GridLimits, density: impl Fn(Vec3) -> f32 + Sync) -> Result<(DensityGrid, Affine3A)> {
    let n = n.clamp(4, 1024) as i32;
    let voxel = 2.0 / n as f32;
    let to_world = Affine3A::from_translation(Vec3::splat(-1.0 + 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    // Dense samples, then as many again in bricks while `from_dense` copies them: 8 B a voxel.
    let count = crate::budget::check_elements::<[f32; 2]>(&format!("procedural medium of {n}^3 voxels (medium.dims)"), (n as u64).pow(3))?;
    let mut values = vec![0.0f32; count];
    use rayon::prelude::*;
    values.par_chunks_mut((n * n) as usize).enumerate().for_each(|(z, slab)| {
        for y in 0..n {
            for x in 0..n {
                let p = to_world.transform_point3(Vec3::new(x as f32, y as f32, z as f32));
                slab[(x + n * y) as usize] = density(p);
            }
        }
    });
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &values, limits)?;
    Ok((grid, to_world))
}
