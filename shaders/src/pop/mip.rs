//! The density's mip pyramid in device memory, uploaded once per solve and read by the merge
//! and upsampling kernels through the prelude `wgsl/mip.wgsl` (a port of `MediumMip::sample`). Every level is
//! bricked like the CPU's density grid: a table of 8^3 bricks, only bricks holding density
//! stored, so a sparse cloud costs its own memory rather than its bounding box's.

use bytemuck::{Pod, Zeroable};
use glam::IVec3;
use rayon::prelude::*;
use std::mem::size_of;

use crate::context::{GpuContext, GpuError};
use volscatter_core::stages::mip::MediumMip;

const BRICK: i32 = 8;
const BRICK_CELLS: usize = 512;

/// Mirrors `struct MipLevel` in wgsl/mip.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
pub struct MipLevel {
    /// Cells per axis; w = offset of the level's brick table in the buffer.
    pub dims: [i32; 4],
    /// Table size in bricks; w = offset of the level's first brick.
    pub bricks: [i32; 4],
    /// Voxels per cell.
    pub scale: [f32; 4],
}

/// Mirrors `struct MipParams` in wgsl/mip.wgsl, the last field of the parameters of every
/// kernel that includes it.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Default)]
pub struct MipParams {
    pub origin: [i32; 4],
    pub a: MipLevel,
    pub b: MipLevel,
    /// Weight of `b`; 1 in y when `b` is read at all.
    pub blend: [f32; 4],
}
const _: () = assert!(size_of::<MipParams>() == 128);

pub struct GpuMip {
    pub buffer: crate::context::Buf,
    origin: [i32; 4],
    levels: Vec<MipLevel>,
    /// Bytes uploaded (benchmarks, and the dense size's comparison).
    pub bytes: u64,
}

/// One level's brick table and the bricks that hold any density, x-fastest cells in each.
fn brick_level(dims: IVec3, data: &[f32]) -> (IVec3, Vec<u32>, Vec<[f32; BRICK_CELLS]>) {
    let t = (dims + IVec3::splat(BRICK - 1)) / BRICK;
    let candidates: Vec<Option<[f32; BRICK_CELLS]>> = (0..t.x * t.y * t.z)
        .into_par_iter()
        .map(|b| {
            let corner = IVec3::new(b % t.x, (b / t.x) % t.y, b / (t.x * t.y)) * BRICK;
            let mut cells = [0.0f32; BRICK_CELLS];
            let mut any = false;
            for (k, v) in cells.iter_mut().enumerate() {
                let c = corner + IVec3::new(k as i32 & 7, (k as i32 >> 3) & 7, k as i32 >> 6);
                if c.cmplt(dims).all() {
                    *v = data[(c.x + dims.x * (c.y + dims.y * c.z)) as usize];
                    any |= *v != 0.0;
                }
            }
            any.then_some(cells)
        })
        .collect();
    let mut table = Vec::with_capacity(candidates.len());
    let mut bricks = Vec::new();
    for c in candidates {
        match c {
            Some(cells) => {
                bricks.push(cells);
                table.push(bricks.len() as u32);
            }
            None => table.push(0),
        }
    }
    (t, table, bricks)
}

impl GpuMip {
    /// All levels in one buffer of u32 words, finest first, each as its table then its bricks.
    pub fn upload(ctx: &GpuContext, mip: &MediumMip) -> Result<Self, GpuError> {
        // Dense size bounds the bricked one: checked before building anything.
        let dense: u64 = mip.levels().map(|(_, _, data)| data.len() as u64).sum();
        ctx.check_storage_size("density mip", dense * 4 + dense / 128 + 64)?;
        let mut words: Vec<u32> = Vec::new();
        let mut levels = Vec::new();
        for (dims, factor, data) in mip.levels() {
            let (t, table, bricks) = brick_level(dims, data);
            let table_at = words.len();
            words.extend_from_slice(&table);
            let bricks_at = words.len();
            words.extend(bricks.iter().flat_map(|b| b.iter().map(|v| v.to_bits())));
            if words.len() > i32::MAX as usize {
                return Err(GpuError::TooLarge(format!("density mip of {} words", words.len())));
            }
            levels.push(MipLevel {
                dims: [dims.x, dims.y, dims.z, table_at as i32],
                bricks: [t.x, t.y, t.z, bricks_at as i32],
                scale: [factor as f32, 0.0, 0.0, 0.0],
            });
        }
        let o = mip.origin();
        let bytes = words.len() as u64 * 4;
        Ok(GpuMip { buffer: ctx.storage_buffer("density mip", bytemuck::cast_slice(&words))?, origin: [o.x, o.y, o.z, 0], levels, bytes })
    }

    /// The mip on the device, kept by the context while its levels are unchanged
    /// (`GpuContext::resident`, keyed by their exact bits): a session's frames upload it once.
    pub fn resident(ctx: &GpuContext, mip: &MediumMip) -> Result<std::sync::Arc<Self>, GpuError> {
        let mut h = volscatter_core::stages::diff::Bits::new();
        h.debug(&mip.origin());
        for (dims, factor, data) in mip.levels() {
            h.debug(&(dims, factor)).bytes(bytemuck::cast_slice(data));
        }
        ctx.resident("density mip", h.finish(), || Self::upload(ctx, mip))
    }

    /// What `MediumMip::sample` reads at `footprint`. Where the CPU reads the density grid
    /// itself (footprint <= 1 with a full-resolution level 0), level 0 holds the same voxels.
    pub fn at_footprint(&self, mip: &MediumMip, footprint: f32) -> MipParams {
        let (l0, l1, t) = mip.blend(footprint).unwrap_or((0, 0, 0.0));
        let second = !(t == 0.0 || l1 == l0);
        MipParams { origin: self.origin, a: self.levels[l0], b: self.levels[l1], blend: [t, second as u32 as f32, 0.0, 0.0] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bricking keeps every value where mip.wgsl's lookup finds it and stores no empty brick.
    #[test]
    fn bricked_level_round_trips_and_skips_empty_bricks() {
        let dims = IVec3::new(19, 9, 10);
        let n = (dims.x * dims.y * dims.z) as usize;
        // Density only in x < 5: of the 3x2x2 bricks, the x = 1, 2 columns stay empty.
        let data: Vec<f32> = (0..n).map(|i| if (i as i32 % dims.x) < 5 { 1.0 + i as f32 } else { 0.0 }).collect();
        let (t, table, bricks) = brick_level(dims, &data);
        assert_eq!(t, IVec3::new(3, 2, 2));
        assert_eq!(bricks.len(), 4);
        for z in 0..dims.z {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    let c = IVec3::new(x, y, z);
                    let b = c >> 3i32;
                    let entry = table[(b.x + t.x * (b.y + t.y * b.z)) as usize];
                    let v = c & IVec3::splat(7);
                    let got = if entry == 0 { 0.0 } else { bricks[entry as usize - 1][(v.x | (v.y << 3) | (v.z << 6)) as usize] };
                    assert_eq!(got, data[(x + dims.x * (y + dims.y * z)) as usize], "cell {c}");
                }
            }
        }
    }
}
