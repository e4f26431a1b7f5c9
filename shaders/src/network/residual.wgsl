// The residual of one iteration (core network/iterate.rs): sum |I_new - I_old| / sum |I_new|
// over the columns' shares, by one workgroup (a strided sum per invocation, then a tree), in
// float32 where the CPU sums in float64 (relative difference ~1e-6 at a million columns).
// Appends it to `residuals` (state[1] counts the iterations) and flags convergence in
// state[0] once it is at most the threshold: the kernels of the iterations recorded after it
// in the same batch then do nothing.

@group(0) @binding(1) var<storage, read_write> state: array<u32>;
@group(0) @binding(2) var<storage, read> partial: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> residuals: array<f32>;

const SIZE: u32 = 256u;
var<workgroup> sums: array<vec2<f32>, 256>;
var<workgroup> done: u32;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(local_invocation_index) li: u32) {
    if (li == 0u) {
        done = state[0];
    }
    if (workgroupUniformLoad(&done) != 0u) {
        return;
    }
    var s = vec2<f32>(0.0);
    for (var c = li; c < params.counts.z; c += SIZE) {
        s += partial[c];
    }
    sums[li] = s;
    workgroupBarrier();
    for (var w = SIZE / 2u; w > 0u; w >>= 1u) {
        if (li < w) {
            sums[li] += sums[li + w];
        }
        workgroupBarrier();
    }
    if (li == 0u) {
        let t = sums[0];
        var r = 0.0;
        if (t.y > 0.0) {
            r = t.x / t.y;
        }
        let it = state[1];
        residuals[it] = r;
        state[1] = it + 1u;
        if (r <= params.albedo_threshold.w) {
            state[0] = 1u;
        }
    }
}
