// Prelude: the density lookup (medium/grid.rs DensityGrid::voxel and ::sample) over the sparse
// bricks as uploaded (upload.rs `BrickedDensity`: the CPU's brick table, bricks and constant
// tiles as u32 words). Reads the including kernel's `params.density_w2i`,
// `params.density_brick_min`, `params.density_brick_dims` and its `density` buffer (module-scope
// names may be used before their declaration in WGSL). Needs affine.wgsl and trilinear.wgsl.

const CONSTANT_BIT: u32 = 0x80000000u;

// DensityGrid::voxel: zero outside the table and in empty bricks.
fn voxel(i: vec3<i32>) -> f32 {
    // >> on i32 is arithmetic, as in Rust: negative indices fall in negative bricks.
    let b = (i >> vec3<u32>(3u)) - params.density_brick_min.xyz;
    let d = vec3<i32>(params.density_brick_dims.xyz);
    if (any(b < vec3<i32>(0)) || any(b >= d)) {
        return 0.0;
    }
    let entry = density[u32(b.x + d.x * (b.y + d.y * b.z))];
    if (entry == 0u) {
        return 0.0;
    }
    if ((entry & CONSTANT_BIT) != 0u) {
        return bitcast<f32>(density[params.density_brick_dims.w + (entry & ~CONSTANT_BIT)]);
    }
    return bitcast<f32>(density[u32(params.density_brick_min.w) + (entry - 1u) * 512u + brick_offset(i)]);
}

// DensityGrid::sample at a world point: trilinear between voxel centres.
fn density_at(x: vec3<f32>) -> f32 {
    let l = lattice(affine(params.density_w2i, x));
    if (!l.ok) {
        return 0.0;
    }
    var c: array<f32, 8>;
    for (var k = 0; k < 8; k++) {
        c[k] = voxel(l.base + corner(k));
    }
    return trilinear1(c, l.t);
}
