// Density lookup shared by the compositor's kernels (prepended to each: WGSL has no
// includes). It reads the including kernel's `params.density_w2i`, `params.density_origin`,
// `params.density_dims` and its `density` buffer; module-scope names may be used before
// their declaration in WGSL.

fn affine(m: array<vec4<f32>, 3>, p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(m[0].xyz, p) + m[0].w, dot(m[1].xyz, p) + m[1].w, dot(m[2].xyz, p) + m[2].w);
}

fn voxel(i: vec3<i32>) -> f32 {
    let d = vec3<i32>(params.density_dims.xyz);
    if (any(i < vec3<i32>(0)) || any(i >= d)) {
        return 0.0;
    }
    return density[u32(i.x + d.x * (i.y + d.y * i.z))];
}

fn density_at(x: vec3<f32>) -> f32 {
    let p = affine(params.density_w2i, x) - vec3<f32>(params.density_origin.xyz);
    let f = floor(p);
    let i = vec3<i32>(f);
    let t = p - f;
    let c00 = mix(voxel(i), voxel(i + vec3<i32>(1, 0, 0)), t.x);
    let c10 = mix(voxel(i + vec3<i32>(0, 1, 0)), voxel(i + vec3<i32>(1, 1, 0)), t.x);
    let c01 = mix(voxel(i + vec3<i32>(0, 0, 1)), voxel(i + vec3<i32>(1, 0, 1)), t.x);
    let c11 = mix(voxel(i + vec3<i32>(0, 1, 1)), voxel(i + vec3<i32>(1, 1, 1)), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}

