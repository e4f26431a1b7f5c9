// POP propagation in one light's grid (volscatter-core solvers/pop/propagate.rs, Eq. 1-8).
// Two kernels per iteration, ping-pong between P/A buffers:
//   emit_accumulate: for each cell, the fractions of P sent front/side/back (HG CDF over the
//     solid angles, Eq. 1-3) and the path one step stands for; adds the view-dependent
//     in-scattered radiance P s/h f_hg(mu, a g) to J (Eq. 7-8) and the energy leaving the grid.
//   gather: each cell collects from its six neighbours with absorption-only transmittance and
//     anisotropy decay (Eq. 2-6).
// Cells: x (u) fastest, d (light direction) slowest. RGB in .xyz of each vec4.
// Params, the bindings, the lobe, path factor and gathering helpers come from the preludes
// (shaders/src/wgsl: hg.wgsl, propagation.wgsl), prepended.

fn cell_of(gid: vec3<u32>) -> u32 {
    return gid.x + params.dims.x * (gid.y + params.dims.y * gid.z);
}

@compute @workgroup_size(4, 4, 4)
fn emit_accumulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid >= params.dims.xyz)) {
        return;
    }
    let c = cell_of(gid);
    let h = params.consts.x;
    let g = params.consts.y;
    let a = a_in[c].xyz;
    let lobe = lobe_fractions(a);
    var kappa = vec3<f32>(1.0);
    if (params.flags.x != 0u) {
        let sigma_tr = sigma_s[c].xyz * (1.0 - abs(g)) + sigma_a[c].xyz + vec3<f32>(params.consts.w);
        kappa = path_factor(a, lobe, sigma_tr, h, params.flags.y != 0u);
    }
    let path = kappa * h;
    store_emit(c, lobe, path);
    let p = p_in[c].xyz;
    let w = p * path / h * params.weight.x;
    j_acc[c] = vec4<f32>(j_acc[c].xyz + w * hg3(mu[c], clamp_a(clamp_a(a) * g)), 0.0);
    // The previous emission's escapes have happened; record this emission's.
    let sides = f32(u32(gid.x == 0u) + u32(gid.x == params.dims.x - 1u) + u32(gid.y == 0u) + u32(gid.y == params.dims.y - 1u));
    var out = lobe.side * sides;
    if (gid.z == params.dims.z - 1u) {
        out += lobe.front;
    }
    if (gid.z == 0u) {
        out += lobe.back;
    }
    esc[2u * c] = vec4<f32>(esc[2u * c].xyz + esc[2u * c + 1u].xyz, 0.0);
    esc[2u * c + 1u] = vec4<f32>(p * out, 0.0);
}

@compute @workgroup_size(4, 4, 4)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid >= params.dims.xyz)) {
        return;
    }
    let nx = params.dims.x;
    let slab = params.dims.x * params.dims.y;
    let dst = cell_of(gid);
    let sa_d = sigma_a[dst].xyz;
    let ss_d = sigma_s[dst].xyz;
    var acc = Gathered(vec3<f32>(0.0), vec3<f32>(0.0));
    // Same neighbour order as the CPU, so the sums round alike.
    if (gid.z > 0u) { add_from(&acc, dst - slab, 0u, 1.0, sa_d, ss_d); }
    if (gid.z + 1u < params.dims.z) { add_from(&acc, dst + slab, 2u, 1.0, sa_d, ss_d); }
    if (gid.x > 0u) { add_from(&acc, dst - 1u, 1u, 1.0, sa_d, ss_d); }
    if (gid.x + 1u < nx) { add_from(&acc, dst + 1u, 1u, 1.0, sa_d, ss_d); }
    if (gid.y > 0u) { add_from(&acc, dst - nx, 1u, 1.0, sa_d, ss_d); }
    if (gid.y + 1u < params.dims.y) { add_from(&acc, dst + nx, 1u, 1.0, sa_d, ss_d); }
    store_gathered(dst, acc);
}
