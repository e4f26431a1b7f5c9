// The sweep of one iteration (core network/iterate.rs): one invocation per column (one pixel
// of one direction's window), walking its particles upstream first,
//   I[p, i] = alpha Q[p, i]                                   (first of the column)
//   I[p, i] = (1 - alpha) I[up, i] + alpha Q[up, i]           (the others)
// in place: I[up, i] is this sweep's value, written by this invocation a step before, as in
// the CPU's column. Also the column's share of the residual: sum |I_new - I_old| and sum
// |I_new| over channels, which the residual kernel adds up.

@group(0) @binding(1) var<storage, read> state: array<u32>;
// Per column: [first, end) in `nodes`, whose index is direction x N + position in its list.
@group(0) @binding(2) var<storage, read> columns: array<vec2<u32>>;
// Per list entry: the particle and its upstream neighbour (NONE for a column's first).
@group(0) @binding(3) var<storage, read> nodes: array<vec2<u32>>;
// Per list entry: the opacity of the gap before it (RGB).
@group(0) @binding(4) var<storage, read> alpha: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> source: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> partial: array<vec2<f32>>;

const NONE: u32 = 0xffffffffu;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = gid.y * params.counts.w + gid.x;
    if (c >= params.counts.z || state[0] != 0u) {
        return;
    }
    let d = params.counts.y;
    let range = columns[c];
    let i = range.x / params.counts.x;
    var change = 0.0;
    var total = 0.0;
    for (var k = range.x; k < range.y; k++) {
        let node = nodes[k];
        let a = alpha[k].xyz;
        let at = node.x * d + i;
        var v: vec3<f32>;
        if (node.y == NONE) {
            v = a * source[at].xyz;
        } else {
            let up = node.y * d + i;
            v = (vec3<f32>(1.0) - a) * radiance[up].xyz + a * source[up].xyz;
        }
        let old = radiance[at].xyz;
        let dv = abs(v - old);
        let av = abs(v);
        change += dv.x + dv.y + dv.z;
        total += av.x + av.y + av.z;
        radiance[at] = vec4<f32>(v, 0.0);
    }
    partial[c] = vec2<f32>(change, total);
}
