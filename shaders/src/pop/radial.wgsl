// POP propagation in a local light's radial grid (volscatter-core solvers/pop/radial/
// propagate.rs): shells x octahedral columns, power per cell. Two kernels per iteration,
// ping-pong between P/A buffers, one invocation per cell (cells: column fastest, shell slowest):
//   emit_accumulate: fractions of P sent outwards (front), to the four angular neighbours
//     (side) and inwards (back), weighted for the faces' sizes and renormalised; the path one
//     step stands for; J += P s / V f_hg(mu, a g); energy leaving through the outer shell.
//   gather: each cell collects from its radial neighbours, its four angular ones, and (in the
//     innermost shell) from the opposite column through the centre, with the anisotropy negated.
// RGB in .xyz of each vec4.
// Params (consts: -, g, ln|g|, -), bindings 0-10, the lobe, path factor and gathering helpers
// come from the preludes (shaders/src/wgsl: hg.wgsl, propagation.wgsl), prepended.

// Bindings 0-10 are declared in propagation.wgsl.
// Per shell: radial length h, 1 / cell volume, front and back face weights.
@group(0) @binding(11) var<storage, read> shells: array<vec4<f32>>;
// Per column, two entries: the four angular neighbours; the opposite column, -, -, -.
@group(0) @binding(12) var<storage, read> columns: array<vec4<u32>>;

@compute @workgroup_size(64)
fn emit_accumulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = gid.x;
    if (c >= params.dims.w) {
        return;
    }
    let k = c / params.dims.y;
    let shell = shells[k];
    let h = shell.x;
    let g = params.consts.y;
    let a = a_in[c].xyz;
    var lobe = lobe_fractions(a);
    let z = lobe.front * shell.z + lobe.back * shell.w + lobe.side * 4.0;
    let inv = select(vec3<f32>(0.0), vec3<f32>(1.0) / max(z, vec3<f32>(1e-30)), z > vec3<f32>(0.0));
    lobe.front = lobe.front * shell.z * inv;
    lobe.back = lobe.back * shell.w * inv;
    lobe.side = lobe.side * inv;
    var kappa = vec3<f32>(1.0);
    if (params.flags.x != 0u) {
        let sigma_tr = sigma_s[c].xyz * (1.0 - abs(g)) + sigma_a[c].xyz;
        kappa = path_factor(a, lobe, sigma_tr, h, true);
    }
    let path = kappa * h;
    store_emit(c, lobe, path);
    var p = p_in[c].xyz;
    var vac = vec3<f32>(0.0);
    if (params.flags.y != 0u && all(sigma_s[c].xyz == vec3<f32>(0.0)) && all(sigma_a[c].xyz == vec3<f32>(0.0))) {
        // Outside the medium the isotropic part escapes (radial/propagate.rs).
        let keep = min(abs(a), vec3<f32>(1.0));
        vac = p * (vec3<f32>(1.0) - keep);
        p = p * keep;
        p_in[c] = vec4<f32>(p, 0.0);
    }
    let w = p * path * (shell.y * params.weight.x);
    let ag = clamp_a(a * g);
    j_acc[c] = vec4<f32>(j_acc[c].xyz + w * hg3(mu[c], ag), 0.0);
    var out = vec3<f32>(0.0);
    if (k == params.dims.z - 1u) {
        out = lobe.front;
    }
    esc[2u * c] = vec4<f32>(esc[2u * c].xyz + esc[2u * c + 1u].xyz + vac, 0.0);
    esc[2u * c + 1u] = vec4<f32>(p * out, 0.0);
}

@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let dst = gid.x;
    if (dst >= params.dims.w) {
        return;
    }
    let slab = params.dims.y;
    let col = dst % slab;
    let k = dst / slab;
    let sa_d = sigma_a[dst].xyz;
    let ss_d = sigma_s[dst].xyz;
    var acc = Gathered(vec3<f32>(0.0), vec3<f32>(0.0));
    // Same order as the CPU, so the sums round alike.
    if (k > 0u) {
        add_from(&acc, dst - slab, 0u, 1.0, sa_d, ss_d);
    } else {
        add_from(&acc, columns[2u * col + 1u].x, 2u, -1.0, sa_d, ss_d);
    }
    if (k + 1u < params.dims.z) {
        add_from(&acc, dst + slab, 2u, 1.0, sa_d, ss_d);
    }
    let nb = columns[2u * col];
    add_from(&acc, nb.x + slab * k, 1u, 1.0, sa_d, ss_d);
    add_from(&acc, nb.y + slab * k, 1u, 1.0, sa_d, ss_d);
    add_from(&acc, nb.z + slab * k, 1u, 1.0, sa_d, ss_d);
    add_from(&acc, nb.w + slab * k, 1u, 1.0, sa_d, ss_d);
    store_gathered(dst, acc);
}
