// Merging one light's accumulation grid into the medium-aligned grid (volscatter-core
// solvers/pop/merge.rs), one dispatch per light in the CPU's order so the sums round alike.
// The first dispatch also writes the density guide (mip.wgsl at the merged cells' footprint)
// and its maximum, which the bilateral filter's range weight needs (positive floats' bit
// patterns order like their values, so an atomicMax on u32 finds it; zero and -0 count as 0).
// affine, the trilinear helpers, mip_sample and j_sample come from the preludes
// (shaders/src/wgsl).

struct Params {
    merged_i2w: array<vec4<f32>, 3>,
    light_w2i: array<vec4<f32>, 3>,
    density_w2i: array<vec4<f32>, 3>,
    merged_dims: vec4<u32>,     // xyz, w = 1 for the first light (write, not add)
    light_dims: vec4<i32>,      // xyz, w = 1 when there is a light to sample
    mip: MipParams,             // wgsl/mip.wgsl
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> mip: array<u32>;
// Binding 2, the light's J (`j_grid`), is declared in wgsl/j_grid.wgsl.
@group(0) @binding(3) var<storage, read_write> merged_j: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> merged_density: array<f32>;
@group(0) @binding(5) var<storage, read_write> max_density: array<atomic<u32>>;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid >= params.merged_dims.xyz)) {
        return;
    }
    let o = gid.x + params.merged_dims.x * (gid.y + params.merged_dims.y * gid.z);
    let x = affine(params.merged_i2w, vec3<f32>(gid));
    let first = params.merged_dims.w != 0u;
    if (first) {
        let rho = mip_sample(affine(params.density_w2i, x));
        merged_density[o] = rho;
        atomicMax(&max_density[0], select(0u, bitcast<u32>(rho), rho > 0.0));
    }
    var j = vec3<f32>(0.0);
    if (!first) {
        j = merged_j[o].xyz;
    }
    if (params.light_dims.w != 0) {
        // LightGrid::sample: the outer half cells hold the edge value.
        j += j_sample(affine(params.light_w2i, x), params.light_dims.xyz, 0.5);
    }
    merged_j[o] = vec4<f32>(j, 0.0);
}
