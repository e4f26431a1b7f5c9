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
        let lo = [lo.x as i64, lo.y as i64, lo.z as i64];
        for (a, l) in lo.into_iter().enumerate() {
            self.bbox_min[a] = self.bbox_min[a].min(l);
            self.bbox_max[a] = self.bbox_max[a].max(l + size - 1);
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
        for i in super::bytes::ones(mask) {
            self.active_voxels = self.active_voxels.saturating_add(1);
            for c in 0..comps {
                self.sum[c] += values[i * comps + c];
            }
            let p = origin + IVec3::new((i >> 6) as i32, ((i >> 3) & 7) as i32, (i & 7) as i32);
            self.extend(p, 1);
        }
        Ok(())
    }
}
