// Per-column sums of a per-cell field (one vec4 of `stride` per cell, at `offset`), so that the
// host reads back one slab instead of the whole grid when it only needs a total (the
// propagation's residual, the escaped energy). column_index comes from wgsl/columns.wgsl.

struct Params {
    dims: vec4<u32>,     // xyz, -
    stride_offset: vec4<u32>,   // stride (vec4s per cell), offset, -, -
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> field: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> sums: array<vec4<f32>>;

// The column's field summed over its depth slices, in order.
fn column_sum(column: u32) -> vec4<f32> {
    let slab = params.dims.x * params.dims.y;
    var s = vec4<f32>(0.0);
    for (var k = 0u; k < params.dims.z; k++) {
        s += field[params.stride_offset.x * (column + k * slab) + params.stride_offset.y];
    }
    return s;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let column = column_index(gid, params.dims.xyz);
    if (column != NO_COLUMN) {
        sums[column] = column_sum(column);
    }
}
