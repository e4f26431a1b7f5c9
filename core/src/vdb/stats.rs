//! What `vdb-info` reports about a tree, computed from the topology and the buffers without
//! densifying anything: tiles count by the voxels they cover, as OpenVDB counts them.

use glam::IVec3;

use super::tree::Visitor;
use crate::error::Result;

#[derive(Clone, Debug)]
pub(crate) struct Stats {
    pub active_voxels: u64,
    pub sum: Vec<f64>,
    pub bbox_min: [i64; 3],
    pub bbox_max: [i64; 3],
}

impl Stats {
    pub fn new(comps: usize) -> Self {
        Stats { active_voxels: 0, sum: vec![0.0; comps], bbox_min: [i64::MAX; 3], bbox_max: [i64::MIN; 3] }
    }
    pub fn is_empty(&self) -> bool {
        self.active_voxels == 0
    }
    fn extend(&mut self, lo: IVec3, size: i64) {
        self.extend_box(lo, lo + IVec3::splat((size - 1) as i32));
    }
    fn extend_box(&mut self, lo: IVec3, hi: IVec3) {
        for (a, (l, h)) in lo.to_array().into_iter().zip(hi.to_array()).enumerate() {
            self.bbox_min[a] = self.bbox_min[a].min(l as i64);
            self.bbox_max[a] = self.bbox_max[a].max(h as i64);
        }
    }
}

impl Visitor for Stats {
    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], active: bool) -> Result<()> {
        if !active {
            return Ok(());
        }
        let n = 1u64 << (3 * log2);
        self.active_voxels = self.active_voxels.saturating_add(n);
        for (s, v) in self.sum.iter_mut().zip(value) {
            *s += v * n as f64;
        }
        self.extend(origin, 1 << log2);
        Ok(())
    }

    fn leaf(&mut self, origin: IVec3, mask: &[u64; 8], values: &[f64]) -> Result<()> {
        let comps = self.sum.len();
        let (mut lo, mut hi) = ([7usize; 3], [0usize; 3]);
        let mut n = 0u64;
        for i in super::bytes::ones(mask) {
            n += 1;
            for c in 0..comps {
                self.sum[c] += values[i * comps + c];
            }
            let p = [i >> 6, (i >> 3) & 7, i & 7];
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if n > 0 {
            self.active_voxels = self.active_voxels.saturating_add(n);
            let v = |p: [usize; 3]| IVec3::new(p[0] as i32, p[1] as i32, p[2] as i32);
            self.extend_box(origin + v(lo), origin + v(hi));
        }
        Ok(())
    }
}
