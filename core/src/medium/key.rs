//! A medium's identity as exact bits, for sessions: a stage kept from an earlier frame is
//! reused only while the key of the medium it came from is unchanged.

use super::{DensityGrid, Medium};

/// A hash of every value a density grid stores (layout, bricks, tiles), FNV-1a over 32-bit
/// words with a final mix: equal grids give equal keys; different grids collide with
/// probability about 2^-64.
pub fn grid_fingerprint(grid: &DensityGrid) -> u64 {
    let (brick_min, brick_dims, table, bricks, constants) = grid.storage();
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut word = |w: u32| h = (h ^ w as u64).wrapping_mul(0x0000_0100_0000_01b3);
    for v in brick_min.to_array().into_iter().chain(brick_dims.to_array()) {
        word(v as u32);
    }
    let (lo, hi) = grid.bbox();
    for v in lo.to_array().into_iter().chain(hi.to_array()) {
        word(v as u32);
    }
    table.iter().for_each(|&t| word(t));
    bricks.iter().flatten().for_each(|v| word(v.to_bits()));
    constants.iter().for_each(|v| word(v.to_bits()));
    // splitmix64's finaliser: FNV's low bits alone mix poorly.
    h ^= h >> 30;
    h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h ^= h >> 27;
    h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

/// Everything about a medium that a solver's light-independent stages read (its voxels, frame,
/// density scale, albedo, g), as exact bits: what a session compares to know the medium did not change.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MediumKey {
    pub(crate) grid: u64,
    /// index_to_world (12 floats), density_scale, albedo, g.
    params: Vec<u32>,
}

impl MediumKey {
    pub fn of(medium: &Medium) -> Self {
        let m = medium.index_to_world;
        let floats = m.matrix3.to_cols_array().into_iter().chain(m.translation.to_array());
        let floats = floats.chain(medium.density_scale.to_array()).chain(medium.albedo.to_array()).chain([medium.g]);
        MediumKey { grid: grid_fingerprint(&medium.grid), params: floats.map(f32::to_bits).collect() }
    }
}
