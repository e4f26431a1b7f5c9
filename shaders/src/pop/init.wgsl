// POP's transmittance sweep (volscatter-core solvers/pop/init.rs) and the single scattering
// of the unscattered light into a fresh accumulation grid (accumulate.rs `add_direct`).
// One invocation per column of the light's grid (u, v), marching along d through the depth
// slices in the CPU's order, so the optical depth sums round alike.
// Outputs: the packets (the propagation's first P buffer), J, and per column the optical
// depth, the light absorbed before scattering and the packets' sum (the energy report and the
// propagation's stopping threshold need only these sums, not the cells).
// hg and column_index come from the preludes (shaders/src/wgsl: hg.wgsl, columns.wgsl).

struct Params {
    dims: vec4<u32>,
    consts: vec4<f32>,   // h, anisotropy of the unscattered light's scattering a0 g (clamped), -, -
    fluence: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> sigma_s: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> sigma_a: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> mu: array<f32>;
@group(0) @binding(4) var<storage, read_write> packets: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> j_acc: array<vec4<f32>>;
// Three vec4 per column: optical depth, absorbed, packets' sum.
@group(0) @binding(6) var<storage, read_write> columns: array<vec4<f32>>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let column = column_index(gid, params.dims.xyz);
    if (column == NO_COLUMN) {
        return;
    }
    let slab = params.dims.x * params.dims.y;
    let h = params.consts.x;
    let a = params.consts.y;
    let fluence = params.fluence.xyz;
    var tau = vec3<f32>(0.0);
    var absorbed = vec3<f32>(0.0);
    var injected = vec3<f32>(0.0);
    for (var k = 0u; k < params.dims.z; k++) {
        let c = column + k * slab;
        let ss = sigma_s[c].xyz;
        let st = ss + sigma_a[c].xyz;
        let t_entry = exp(-tau);
        let direct = fluence * t_entry * exp(-st * (0.5 * h));
        let lost = fluence * t_entry * (vec3<f32>(1.0) - exp(-st * h));
        // Fraction of the extinguished light that is scattered: sigma_s / sigma_t.
        let frac_s = select(vec3<f32>(0.0), ss / max(st, vec3<f32>(1e-12)), st > vec3<f32>(1e-12));
        let pk = lost * frac_s;
        absorbed += lost - pk;
        tau += st * h;
        packets[c] = vec4<f32>(pk, 0.0);
        injected += pk;
        j_acc[c] = vec4<f32>(direct * hg(mu[c], a), 0.0);
    }
    columns[3u * column] = vec4<f32>(tau, 0.0);
    columns[3u * column + 1u] = vec4<f32>(absorbed, 0.0);
    columns[3u * column + 2u] = vec4<f32>(injected, 0.0);
}
