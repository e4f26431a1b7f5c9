//! Merging the lights' accumulation grids into one medium-aligned grid (Sec. 5.3), with the
//! density prefiltered to the same cells as the coarse guide for upsampling.

use glam::Vec3;
use rayon::prelude::*;

use super::light_grid::LightGrid;
use crate::stages::mip::MediumMip;
use crate::error::Result;
use crate::medium::Medium;
use crate::stages::upsample::{footprint, Merged};
use crate::stages::ScatteringGrid;

/// `lights`: each light's grid and its accumulation J, summed in this order.
pub fn merge(medium: &Medium, mip: &MediumMip, lights: &[(&LightGrid, &[Vec3])], resolution: u32) -> Result<Merged> {
    let mut j = ScatteringGrid::over_medium(medium, resolution)?;
    let fp = footprint(medium, &j);
    let [nx, ny, _] = j.dims;
    let frame = j.index_to_world;
    let w2i = medium.world_to_index;
    let mut density = vec![0.0f32; j.len()];
    j.data.par_chunks_mut((nx * ny) as usize).zip(density.par_chunks_mut((nx * ny) as usize)).enumerate().for_each(|(k, (out, dens))| {
        for jj in 0..ny {
            for i in 0..nx {
                let x = frame.transform_point3(Vec3::new(i as f32, jj as f32, k as f32));
                let o = (i + nx * jj) as usize;
                dens[o] = mip.sample(medium, w2i.transform_point3(x), fp);
                out[o] = lights.iter().map(|(g, acc)| g.sample(acc, x)).sum();
            }
        }
    });
    Ok(Merged { j, density })
}
