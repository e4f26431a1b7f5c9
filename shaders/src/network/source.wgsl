// The scattered source of one iteration of Eq. 2 (core network/iterate.rs):
//   Q[p, i] = E[p, i] + albedo sum_d P[i, d] I[p, d]
// an (N x D) x (D x D)^T matrix product in 16 x 16 tiles: a workgroup holds 16 particles' I
// and 16 directions' phase rows over 16 d at a time in workgroup memory. Each invocation sums
// its d in order 0..D-1, as the CPU does, so the two differ only by rounding (fused
// multiply-adds where the driver contracts them).
// Once the residual kernel has flagged convergence (state[0]) the iterations recorded after it
// do nothing, so a batch of iterations between two readbacks stops where the CPU stops.

@group(0) @binding(1) var<storage, read> state: array<u32>;
@group(0) @binding(2) var<storage, read> phase: array<f32>;
@group(0) @binding(3) var<storage, read> first: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> radiance: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> source: array<vec4<f32>>;

const TILE: u32 = 16u;
var<workgroup> tile_i: array<vec4<f32>, 256>;  // [particle][d]
var<workgroup> tile_p: array<f32, 256>;        // [direction][d]
var<workgroup> done: u32;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if (lid.x == 0u && lid.y == 0u) {
        done = state[0];
    }
    if (workgroupUniformLoad(&done) != 0u) {
        return;
    }
    let n = params.counts.x;
    let d = params.counts.y;
    let i = wid.x * TILE + lid.x;
    let p = wid.y * TILE + lid.y;
    let row = wid.x * TILE + lid.y;
    var acc = vec3<f32>(0.0);
    for (var d0 = 0u; d0 < d; d0 += TILE) {
        let dd = d0 + lid.x;
        var l = vec4<f32>(0.0);
        var w = 0.0;
        if (p < n && dd < d) {
            l = radiance[p * d + dd];
        }
        if (row < d && dd < d) {
            w = phase[row * d + dd];
        }
        tile_i[lid.y * TILE + lid.x] = l;
        tile_p[lid.y * TILE + lid.x] = w;
        workgroupBarrier();
        let m = min(TILE, d - d0);
        for (var k = 0u; k < m; k++) {
            acc += tile_i[lid.y * TILE + k].xyz * tile_p[lid.x * TILE + k];
        }
        workgroupBarrier();
    }
    if (p < n && i < d) {
        source[p * d + i] = vec4<f32>(first[p * d + i].xyz + params.albedo_threshold.xyz * acc, 0.0);
    }
}
