//! 3D joint bilateral upsampling (Sec. 4.4, after Kopf et al. 2007) of the merged grid to the
//! output grid, guided by the density, and the final S = sigma_s(x) J(x).
//!
//! What is upsampled is J, the in-scattered radiance per unit sigma_s, not S: J is smooth
//! (light varies over transport lengths), sigma_s carries the voxel detail, so multiplying
//! after upsampling restores the density's full resolution exactly where the medium is. The
//! range weight keeps J from bleeding across density edges: at the rim of a cloud the coarse
//! cells half outside hold the bright unshadowed light, and a fine voxel inside the cloud should
//! take its light from coarse cells of similar density.

use glam::{IVec3, Vec3};
use rayon::prelude::*;

use super::merge::{footprint, Merged};
use super::mip::MediumMip;
use super::settings::PopSettings;
use crate::error::Result;
use crate::medium::Medium;
use crate::solvers::ScatteringGrid;

pub fn upsample(medium: &Medium, mip: &MediumMip, merged: &Merged, settings: &PopSettings) -> Result<ScatteringGrid> {
    let mut out = ScatteringGrid::over_medium(medium, settings.output_resolution)?;
    let fp = footprint(medium, &out);
    let [nx, ny, _] = out.dims;
    let frame = out.index_to_world;
    let coarse = &merged.j;
    let to_coarse = coarse.index_to_world.inverse();
    let cd = IVec3::new(coarse.dims[0] as i32, coarse.dims[1] as i32, coarse.dims[2] as i32);
    let w2i = medium.world_to_index;
    let max_density = merged.density.iter().fold(0.0f32, |m, &v| m.max(v)).max(1e-12);
    let inv_range = 1.0 / (2.0 * (settings.range_sigma * max_density).powi(2));
    let inv_spatial = 1.0 / (2.0 * settings.spatial_sigma * settings.spatial_sigma);
    let radius = (2.0 * settings.spatial_sigma).ceil().max(1.0) as i32;
    out.data.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, slab)| {
        for j in 0..ny {
            for i in 0..nx {
                let x = frame.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
                let rho = mip.sample(medium, w2i.transform_point3(x), fp);
                if rho <= 0.0 {
                    continue;
                }
                let q = to_coarse.transform_point3(x);
                let jv = if settings.upsample {
                    let base = q.floor().as_ivec3();
                    let mut sum = Vec3::ZERO;
                    let mut wsum = 0.0f32;
                    for dz in (1 - radius)..=radius {
                        for dy in (1 - radius)..=radius {
                            for dx in (1 - radius)..=radius {
                                let c = base + IVec3::new(dx, dy, dz);
                                if c.cmplt(IVec3::ZERO).any() || c.cmpge(cd).any() {
                                    continue;
                                }
                                let ci = (c.x + cd.x * (c.y + cd.y * c.z)) as usize;
                                let ds = (q - c.as_vec3()).length_squared();
                                let dr = rho - merged.density[ci];
                                let w = (-ds * inv_spatial - dr * dr * inv_range).exp();
                                sum += coarse.data[ci] * w;
                                wsum += w;
                            }
                        }
                    }
                    if wsum > 1e-20 { sum / wsum } else { coarse.sample_index(q) }
                } else {
                    coarse.sample_index(q)
                };
                slab[(i + nx * j) as usize] = medium.sigma_s(rho) * jv;
            }
        }
    });
    Ok(out)
}
