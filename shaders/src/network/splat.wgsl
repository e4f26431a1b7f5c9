// The splat's accumulation (core network/splat.rs `accumulate`), as a gather: one invocation
// per grid point, over its tile's particles in index order (the CPU's order of summation:
// the CPU adds, particle by particle, only where the point is in the kernel box), taking
// those whose kernel box holds the point:
//   num += value exp(-|x - x_p|^2 inv_spatial - (rho - rho_p)^2 inv_range),  den += the weight.
// The host divides and adds sigma_s (`finish`). One workgroup per 4^3 points; a dispatch
// covers the z layers of workgroups from `params.pairs.z`, so that the host can look at
// cancellation between dispatches.

// Per grid point: world position, unscaled density (0 outside the medium).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> particles: array<Particle>;
@group(0) @binding(3) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read> ranges: array<vec2<u32>>;
// Per grid point: the weighted sum of values (xyz) and of the weights (w).
@group(0) @binding(5) var<storage, read_write> sums: array<vec4<f32>>;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ijk = gid + vec3<u32>(0u, 0u, 4u * params.pairs.z);
    if (any(ijk >= params.dims.xyz)) {
        return;
    }
    let c = ijk.x + params.dims.x * (ijk.y + params.dims.y * ijk.z);
    let pt = points[c];
    var num = vec3<f32>(0.0);
    var den = 0.0;
    if (pt.w > 0.0) {
        let at = vec3<i32>(ijk);
        let run = ranges[tile_of(ijk)];
        for (var k = run.x; k < run.y; k++) {
            let p = particles[keys[k].y];
            if (all(at >= p.lo.xyz) && all(at <= p.hi.xyz)) {
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
