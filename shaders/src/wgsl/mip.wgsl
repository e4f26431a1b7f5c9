// Prelude: the density's mip pyramid (volscatter-core solvers/pop/mip.rs `MediumMip::sample`),
// of pop/merge.wgsl and pop/upsample.wgsl. Needs affine.wgsl and trilinear.wgsl. All levels lie in one
// buffer `mip` of u32 words, each level bricked (pop/mip.rs): a table of 8^3 bricks, 0 for an
// empty brick, else 1 + the index of its stored voxels (floats as bits), so empty space costs
// one word per brick. A kernel samples at one footprint, so the two levels and their blend
// weight (`MediumMip::blend`) come in its `params.mip` (the last field of its Params). A footprint that would read the
// density grid itself is served by level 0 when that level is the grid (factor 1): same values,
// same trilinear weights.

struct MipLevel {
    dims: vec4<i32>,     // cells per axis, w = offset of the level's brick table in `mip`
    bricks: vec4<i32>,   // table size in bricks, w = offset of the level's first brick
    scale: vec4<f32>,    // voxels per cell, -, -, -
};

struct MipParams {
    origin: vec4<i32>,   // index-space corner of cell 0 of every level
    a: MipLevel,
    b: MipLevel,
    blend: vec4<f32>,    // x = weight of the second level, y = 1 when it is read at all
};

fn mip_cell(l: MipLevel, c: vec3<i32>) -> f32 {
    if (any(c < vec3<i32>(0)) || any(c >= l.dims.xyz)) {
        return 0.0;
    }
    let b = c >> vec3<u32>(3u);
    let entry = mip[u32(l.dims.w + b.x + l.bricks.x * (b.y + l.bricks.y * b.z))];
    if (entry == 0u) {
        return 0.0;
    }
    return bitcast<f32>(mip[u32(l.bricks.w) + (entry - 1u) * 512u + brick_offset(c)]);
}

// MediumMip::sample_level + Level::sample.
fn mip_level_sample(l: MipLevel, p_index: vec3<f32>) -> f32 {
    let f = l.scale.x;
    let q = (p_index - vec3<f32>(params.mip.origin.xyz) - vec3<f32>(0.5 * (f - 1.0))) / f;
    let lat = lattice(q);
    if (!lat.ok) {
        return 0.0;
    }
    var c: array<f32, 8>;
    for (var k = 0; k < 8; k++) {
        c[k] = mip_cell(l, lat.base + corner(k));
    }
    return trilinear1(c, lat.t);
}

// MediumMip::sample at the kernel's footprint.
fn mip_sample(p_index: vec3<f32>) -> f32 {
    let a = mip_level_sample(params.mip.a, p_index);
    if (params.mip.blend.y == 0.0) {
        return a;
    }
    return lerp1(a, mip_level_sample(params.mip.b, p_index), params.mip.blend.x);
}
