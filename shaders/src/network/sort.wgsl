// One stage (k, j) of a bitonic sort of `keys` in independent lists of `len` (a power of two)
// entries each, ascending by (x, y, z) (then w): one invocation per entry, the lower of each
// compared pair doing the compare-and-swap. The host records every stage: k = 2, 4, .., len;
// j = k / 2, .., 1. Keys are unique where the caller needs a unique order (the particle index
// in z), so the result does not depend on the sort's instability.

struct Params {
    stage: vec4<u32>,   // k, j, list length, entries in all
    rows: vec4<u32>,    // invocations per dispatch row, -, -, -
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> keys: array<vec4<u32>>;

fn less(a: vec4<u32>, b: vec4<u32>) -> bool {
    if (a.x != b.x) {
        return a.x < b.x;
    }
    if (a.y != b.y) {
        return a.y < b.y;
    }
    if (a.z != b.z) {
        return a.z < b.z;
    }
    return a.w < b.w;
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * params.rows.x + gid.x;
    if (i >= params.stage.w) {
        return;
    }
    let l = i ^ params.stage.y;
    if (l <= i) {
        return;
    }
    let a = keys[i];
    let b = keys[l];
    // Ascending where the entry's bit k (within its list) is clear: the bitonic merge network.
    let ascending = ((i & (params.stage.z - 1u)) & params.stage.x) == 0u;
    if (select(less(a, b), less(b, a), ascending)) {
        keys[i] = b;
        keys[l] = a;
    }
}
