// The splat's accumulation (core network/splat.rs `accumulate`), as a gather: one invocation
// per grid point, over every particle in index order (the CPU's order of summation), taking
// those whose kernel box holds the point:
//   num += value exp(-|x - x_p|^2 inv_spatial - (rho - rho_p)^2 inv_range),  den += the weight.
// The host divides and adds sigma_s (`finish`). Cost grid points x particles box tests, which
// a GPU does at memory speed; the dispatch covers `params.cells.y` points from `params.cells.x`
// so that the host can look at cancellation between chunks.

struct Params {
    dims: vec4<u32>,       // grid x, y, z, particles
    cells: vec4<u32>,      // first point of this chunk, points in it, invocations per dispatch row, -
    inv_range: vec4<f32>,  // 1 / (2 (range sigma x largest density)^2), -, -, -
};

// Mirrors `GpuParticle` in network/splat.rs.
struct Particle {
    position_inv_spatial: vec4<f32>,
    lo: vec4<i32>,
    hi: vec4<i32>,
    value_density: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
// Per grid point: world position, unscaled density (0 outside the medium).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> particles: array<Particle>;
// Per grid point: the weighted sum of values (xyz) and of the weights (w).
@group(0) @binding(3) var<storage, read_write> sums: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let local = gid.y * params.cells.z + gid.x;
    if (local >= params.cells.y) {
        return;
    }
    let c = params.cells.x + local;
    let pt = points[c];
    var num = vec3<f32>(0.0);
    var den = 0.0;
    if (pt.w > 0.0) {
        let nx = params.dims.x;
        let ny = params.dims.y;
        let ijk = vec3<i32>(vec3<u32>(c % nx, (c / nx) % ny, c / (nx * ny)));
        for (var i = 0u; i < params.dims.w; i++) {
            let p = particles[i];
            if (all(ijk >= p.lo.xyz) && all(ijk <= p.hi.xyz)) {
                let dx = pt.xyz - p.position_inv_spatial.xyz;
                let ds = dx.x * dx.x + dx.y * dx.y + dx.z * dx.z;
                let dr = pt.w - p.value_density.w;
                let w = exp(-ds * p.position_inv_spatial.w - dr * dr * params.inv_range.x);
                num += p.value_density.xyz * w;
                den += w;
            }
        }
    }
    sums[c] = vec4<f32>(num, den);
}
