// Prelude of pop/merge.wgsl and pop/upsample.wgsl: the J grid each reads (binding 2; dense, x
// fastest, RGB in .xyz: merge reads one light's grid, upsample the merged one) and its
// trilinear lookup. Needs trilinear.wgsl.

@group(0) @binding(2) var<storage, read> j_grid: array<vec4<f32>>;

// Trilinear at grid-index point p of a grid of `dims` points, corners clamped into the grid;
// zero outside [-margin, dims - 1 + margin], points within the margin taking the edge value
// (LightGrid::sample: margin 0.5; ScatteringGrid::sample_index: margin 0).
fn j_sample(p: vec3<f32>, dims: vec3<i32>, margin: f32) -> vec3<f32> {
    let edge = vec3<f32>(dims - vec3<i32>(1));
    if (!inside(p, vec3<f32>(-margin), edge + vec3<f32>(margin))) {
        return vec3<f32>(0.0);
    }
    let l = lattice(clamp(p, vec3<f32>(0.0), edge));
    var c: array<vec3<f32>, 8>;
    for (var k = 0; k < 8; k++) {
        c[k] = j_grid[clamped_index(l.base + corner(k), dims)].xyz;
    }
    return trilinear3(c, l.t);
}
