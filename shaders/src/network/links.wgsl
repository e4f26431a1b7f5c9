// Per (direction of the chunk, position k in its sorted list): the list entry (the column
// order), the particle's upstream neighbour (the entry before it when in the same pixel) and
// the opacity of the gap between them, as core network/visibility.rs `build`:
//   boundary: tau = max(tau_b - tau_a, 0) (tau_b alone without a neighbour),
//   segment: the gap's marched optical depth per metre times its depth along w.

@group(0) @binding(4) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read> to_boundary: array<vec4<f32>>;
// Per (direction, list position): the particle there.
@group(0) @binding(6) var<storage, read_write> order: array<u32>;
// Per (direction, particle): its upstream neighbour or NONE, and its gap's opacity (RGB).
@group(0) @binding(7) var<storage, read_write> up: array<u32>;
@group(0) @binding(8) var<storage, read_write> alpha: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = invocation(gid);
    let n = params.counts.x;
    if (i >= n * params.counts.w) {
        return;
    }
    let d = i / n;
    let k = i % n;
    let at = d * params.counts.z + k;
    let key = keys[at];
    let b = key.z;
    var a = NONE;
    if (k > 0u && keys[at - 1u].x == key.x) {
        a = keys[at - 1u].z;
    }
    order[i] = b;
    up[d * n + b] = a;
    let w = basis[3u * d + 2u].xyz;
    let step = params.misc.x;
    var tau = vec3<f32>(0.0);
    if (params.modes.y == 0u) {
        tau = to_boundary[d * n + b].xyz;
        if (a != NONE) {
            tau = max(tau - to_boundary[d * n + a].xyz, vec3<f32>(0.0));
        }
    } else if (a == NONE) {
        tau = optical_depth(positions[b].xyz, -w, NO_LIMIT, step, BOUNDARY_STEPS);
    } else {
        let xa = positions[a].xyz;
        let gap = positions[b].xyz - xa;
        let len = sqrt(dot3(gap, gap));
        if (len > 0.0) {
            tau = optical_depth(xa, gap / len, len, step, SEGMENT_STEPS) * (max(dot3(gap, w), 0.0) / len);
        }
    }
    alpha[d * n + b] = vec4<f32>(vec3<f32>(1.0) - exp(-tau), 0.0);
}
