// Density lookup shared by the compositor's kernels (prepended to each: WGSL has no
// includes). It reads the including kernel's `params.density_w2i`, `params.density_brick_min`,
// `params.density_brick_dims` and its `density` buffer (upload.rs `BrickedDensity`: the CPU's
// sparse brick table, bricks and constant tiles as u32 words); module-scope names may be used
// before their declaration in WGSL.

fn affine(m: array<vec4<f32>, 3>, p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(m[0].xyz, p) + m[0].w, dot(m[1].xyz, p) + m[1].w, dot(m[2].xyz, p) + m[2].w);
}

const BRICK_LOG2: u32 = 3u;
const CONSTANT_BIT: u32 = 0x80000000u;

// DensityGrid::voxel: zero outside the table and in empty bricks.
fn voxel(i: vec3<i32>) -> f32 {
    // >> on i32 is arithmetic, as in Rust: negative indices fall in negative bricks.
    let b = (i >> vec3<u32>(BRICK_LOG2)) - params.density_brick_min.xyz;
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
    let l = i & vec3<i32>(7);
    let offset = u32(l.x | (l.y << BRICK_LOG2) | (l.z << (2u * BRICK_LOG2)));
    return bitcast<f32>(density[u32(params.density_brick_min.w) + (entry - 1u) * 512u + offset]);
}

// DensityGrid::sample: trilinear between voxel centres.
fn density_at(x: vec3<f32>) -> f32 {
    let p = affine(params.density_w2i, x);
    let f = floor(p);
    let i = vec3<i32>(f);
    let t = p - f;
    let c00 = mix(voxel(i), voxel(i + vec3<i32>(1, 0, 0)), t.x);
    let c10 = mix(voxel(i + vec3<i32>(0, 1, 0)), voxel(i + vec3<i32>(1, 1, 0)), t.x);
    let c01 = mix(voxel(i + vec3<i32>(0, 0, 1)), voxel(i + vec3<i32>(1, 0, 1)), t.x);
    let c11 = mix(voxel(i + vec3<i32>(0, 1, 1)), voxel(i + vec3<i32>(1, 1, 1)), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}
