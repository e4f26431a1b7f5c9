// What network's splat kernels share (shaders/src/network/bin.wgsl, ranges.wgsl, splat.wgsl):
// their parameters (mirrored by `SplatParams` in network/splat.rs) and the particle record
// (`GpuParticle`). The output grid is cut into tiles of T^3 points; each particle is listed
// in every tile its kernel box overlaps, as (tile, particle) keys sorted by the bitonic sort,
// so a grid point visits only its tile's particles, in index order (the CPU's order).

struct Params {
    dims: vec4<u32>,       // grid x, y, z, particles
    tiles: vec4<u32>,      // tile side T, tiles along x, y, z
    pairs: vec4<u32>,      // (tile, particle) pairs, sorted list length, first tile layer of this dispatch, invocations per dispatch row
    inv_range: vec4<f32>,  // 1 / (2 (range sigma x largest density)^2), -, -, -
};

// Mirrors `GpuParticle` in network/splat.rs: kernel box [lo, hi] in grid indices.
struct Particle {
    position_inv_spatial: vec4<f32>,
    lo: vec4<i32>,
    hi: vec4<i32>,
    value_density: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;

// The sorted list's padding (sorted last).
const PAD: u32 = 0xffffffffu;

fn tile_of(ijk: vec3<u32>) -> u32 {
    let t = ijk / params.tiles.x;
    return t.x + params.tiles.y * (t.y + params.tiles.z * t.z);
}
