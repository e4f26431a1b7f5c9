// The density's mip pyramid (volscatter-core solvers/pop/mip.rs `MediumMip::sample`), shared
// by merge.wgsl and upsample.wgsl (prepended: WGSL has no includes). All levels lie in one
// buffer `mip` of u32 words, each level bricked (pop/mip.rs): a table of 8^3 bricks, 0 for an
// empty brick, else 1 + the index of its stored voxels (floats as bits), so empty space costs
// one word per brick. A kernel samples at one footprint, so the two levels and their blend
// weight (`MediumMip::blend`) come in its `params.mip_*` fields. A footprint that would read the
// density grid itself is served by level 0 when that level is the grid (factor 1): same values,
// same trilinear weights.

struct MipLevel {
    dims: vec4<i32>,     // cells per axis, w = offset of the level's brick table in `mip`
    bricks: vec4<i32>,   // table size in bricks, w = offset of the level's first brick
    scale: vec4<f32>,    // voxels per cell, -, -, -
};

fn affine(m: array<vec4<f32>, 3>, p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(m[0].xyz, p) + m[0].w, dot(m[1].xyz, p) + m[1].w, dot(m[2].xyz, p) + m[2].w);
}

fn mip_cell(l: MipLevel, c: vec3<i32>) -> f32 {
    if (any(c < vec3<i32>(0)) || any(c >= l.dims.xyz)) {
        return 0.0;
    }
    let b = c >> vec3<u32>(3u);
    let entry = mip[u32(l.dims.w + b.x + l.bricks.x * (b.y + l.bricks.y * b.z))];
    if (entry == 0u) {
        return 0.0;
    }
    let v = c & vec3<i32>(7);
    return bitcast<f32>(mip[u32(l.bricks.w) + (entry - 1u) * 512u + u32(v.x | (v.y << 3u) | (v.z << 6u))]);
}

// MediumMip::sample_level + Level::sample.
fn mip_level_sample(l: MipLevel, p_index: vec3<f32>) -> f32 {
    let f = l.scale.x;
    let q = (p_index - vec3<f32>(params.mip_origin.xyz) - vec3<f32>(0.5 * (f - 1.0))) / f;
    let fl = floor(q);
    let i = vec3<i32>(fl);
    let t = q - fl;
    let c00 = mip_cell(l, i) * (1.0 - t.x) + mip_cell(l, i + vec3<i32>(1, 0, 0)) * t.x;
    let c10 = mip_cell(l, i + vec3<i32>(0, 1, 0)) * (1.0 - t.x) + mip_cell(l, i + vec3<i32>(1, 1, 0)) * t.x;
    let c01 = mip_cell(l, i + vec3<i32>(0, 0, 1)) * (1.0 - t.x) + mip_cell(l, i + vec3<i32>(1, 0, 1)) * t.x;
    let c11 = mip_cell(l, i + vec3<i32>(0, 1, 1)) * (1.0 - t.x) + mip_cell(l, i + vec3<i32>(1, 1, 1)) * t.x;
    return (c00 * (1.0 - t.y) + c10 * t.y) * (1.0 - t.z) + (c01 * (1.0 - t.y) + c11 * t.y) * t.z;
}

// MediumMip::sample at the kernel's footprint: params.mip_blend.x = weight of the second level,
// .y = 1 when the second level is read at all.
fn mip_sample(p_index: vec3<f32>) -> f32 {
    let a = mip_level_sample(params.mip_a, p_index);
    if (params.mip_blend.y == 0.0) {
        return a;
    }
    let t = params.mip_blend.x;
    return a * (1.0 - t) + mip_level_sample(params.mip_b, p_index) * t;
}
