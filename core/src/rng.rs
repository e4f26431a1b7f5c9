//! Deterministic random numbers: one PCG32 stream per pixel / voxel / path so that renders are
//! reproducible for a seed whatever the thread count.

use rand::RngCore;
use rand_pcg::Pcg32;

pub struct Rng(Pcg32);

impl Rng {
    /// `stream` selects an independent sequence (pixel index, voxel index, ...).
    pub fn new(seed: u64, stream: u64) -> Self {
        Rng(Pcg32::new(seed ^ 0x853c_49e6_748f_ea9b, stream.wrapping_mul(2).wrapping_add(1)))
    }
    /// Uniform in [0, 1).
    #[inline]
    pub fn f32(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
    #[inline]
    pub fn pair(&mut self) -> [f32; 2] {
        [self.f32(), self.f32()]
    }
}
