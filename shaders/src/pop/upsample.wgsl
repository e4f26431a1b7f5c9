// Joint bilateral upsampling of the merged J to the output grid, guided by the density, and
// S = sigma_s J (volscatter-core solvers/pop/upsample.rs), one invocation per output point,
// same neighbourhood and order as the CPU. The density comes from mip.wgsl at the output
// grid's footprint; the coarse density and its maximum from merge.wgsl. affine, the trilinear
// helpers, mip_sample and j_sample (ScatteringGrid::sample_index with margin 0) come from the
// preludes (shaders/src/wgsl).

struct Params {
    out_i2w: array<vec4<f32>, 3>,
    to_coarse: array<vec4<f32>, 3>,   // world -> merged grid index
    density_w2i: array<vec4<f32>, 3>,
    out_dims: vec4<u32>,
    coarse_dims: vec4<i32>,           // xyz, w = 1: bilateral, 0: trilinear
    bilateral: vec4<f32>,             // range sigma, 1 / (2 spatial sigma^2), radius, -
    sigma_s_per_density: vec4<f32>,   // albedo * density_scale
    mip: MipParams,             // wgsl/mip.wgsl
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> mip: array<u32>;
// Binding 2, the merged J (`j_grid`), is declared in wgsl/j_grid.wgsl.
@group(0) @binding(3) var<storage, read> coarse_density: array<f32>;
@group(0) @binding(4) var<storage, read> max_density: array<u32>;
@group(0) @binding(5) var<storage, read_write> out_s: array<vec4<f32>>;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid >= params.out_dims.xyz)) {
        return;
    }
    let o = gid.x + params.out_dims.x * (gid.y + params.out_dims.y * gid.z);
    let x = affine(params.out_i2w, vec3<f32>(gid));
    let rho = mip_sample(affine(params.density_w2i, x));
    if (rho <= 0.0) {
        out_s[o] = vec4<f32>(0.0);
        return;
    }
    let q = affine(params.to_coarse, x);
    var jv: vec3<f32>;
    if (params.coarse_dims.w != 0) {
        let cd = params.coarse_dims.xyz;
        let max_rho = max(bitcast<f32>(max_density[0]), 1e-12);
        let range_width = params.bilateral.x * max_rho;
        let inv_range = 1.0 / (2.0 * (range_width * range_width));
        let inv_spatial = params.bilateral.y;
        let radius = i32(params.bilateral.z);
        let base = vec3<i32>(floor(q));
        var sum = vec3<f32>(0.0);
        var wsum = 0.0;
        for (var dz = 1 - radius; dz <= radius; dz++) {
            for (var dy = 1 - radius; dy <= radius; dy++) {
                for (var dx = 1 - radius; dx <= radius; dx++) {
                    let c = base + vec3<i32>(dx, dy, dz);
                    if (any(c < vec3<i32>(0)) || any(c >= cd)) {
                        continue;
                    }
                    let ci = u32(c.x + cd.x * (c.y + cd.y * c.z));
                    let e = q - vec3<f32>(c);
                    let ds = dot(e, e);
                    let dr = rho - coarse_density[ci];
                    let w = exp(-ds * inv_spatial - dr * dr * inv_range);
                    sum += j_grid[ci].xyz * w;
                    wsum += w;
                }
            }
        }
        if (wsum > 1e-20) {
            jv = sum / wsum;
        } else {
            jv = j_sample(q, params.coarse_dims.xyz, 0.0);
        }
    } else {
        jv = j_sample(q, params.coarse_dims.xyz, 0.0);
    }
    out_s[o] = vec4<f32>(params.sigma_s_per_density.xyz * rho * jv, 0.0);
}
