// What network's visibility kernels share (shaders/src/network/keys.wgsl, links.wgsl): their
// parameters (mirrored by `VisibilityParams` in network/visibility.rs), the medium and the
// particles, the per-direction bases, and the CPU's key arithmetic (core network/visibility.rs
// `sort_key`), written out operation by operation as glam does it (dot products as x + y + z
// in that order) so that the bins and depths are the CPU's bit for bit.

struct Params {
    density_w2i: array<vec4<f32>, 3>,
    density_brick_min: vec4<i32>,      // wgsl/density.wgsl
    density_brick_dims: vec4<u32>,
    density_scale: vec4<f32>,
    bounds_lo: vec4<f32>,
    bounds_hi: vec4<f32>,
    centre_radius: vec4<f32>,          // the windows' bounding sphere: centre, radius
    counts: vec4<u32>,                 // particles N, window side M, list length P (a power of two >= N), directions in this chunk
    modes: vec4<u32>,                  // invocations per dispatch row, opacity (0 boundary, 1 segment), -, -
    misc: vec4<f32>,                   // shortest march step, -, -, -
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
// Per particle: world position (xyz).
@group(0) @binding(2) var<storage, read> positions: array<vec4<f32>>;
// Per direction of the chunk: u, v (the window's axes, core sampling::orthonormal_basis) and w
// (the direction light travels), as three vec4.
@group(0) @binding(3) var<storage, read> basis: array<vec4<f32>>;

// No upstream particle (core network/visibility.rs NONE); also the key of a list's padding.
const NONE: u32 = 0xffffffffu;
// Most march steps to the boundary and along a gap (visibility.rs BOUNDARY_STEPS, SEGMENT_STEPS).
const BOUNDARY_STEPS: u32 = 512u;
const SEGMENT_STEPS: u32 = 256u;
// The CPU marches to the boundary with t_max infinite: no ray_box span reaches this.
const NO_LIMIT: f32 = 3.4e38;

fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// The invocation's index over a 2D dispatch of rows of `params.modes.x` invocations.
fn invocation(gid: vec3<u32>) -> u32 {
    return gid.y * params.modes.x + gid.x;
}
