// Prelude of POP's two propagation kernels (pop/propagate.wgsl: one distant light's
// rectilinear grid; pop/radial.wgsl: one local light's radial grid): their common parameters,
// their bindings 0-10 (a kernel adds its own from 11), the per-cell emission record and the
// gathering of a neighbour's packets. Needs hg.wgsl.

// Mirrored by `PropagateParams` in pop/mod.rs.
struct Params {
    dims: vec4<u32>,    // propagate: cells per axis; radial: n, columns (n^2), shells, cells
    consts: vec4<f32>,  // h (propagate) or -, g, ln|g|, 1/escape length (propagate)
    flags: vec4<u32>,   // diffusion_correction, drift_matched (propagate) / vacuum_escape (radial)
    weight: vec4<f32>,  // J weight of this emission (0.5 for the packets' birth cells), -, -, -
};

// Read-only as the layout says (pop/mod.rs `PROPAGATION_READ_ONLY`).
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> sigma_s: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> sigma_a: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> mu: array<f32>;
// Read-write: the radial kernel removes what escapes from empty cells (vacuum_escape).
@group(0) @binding(4) var<storage, read_write> p_in: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> a_in: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> emit: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> j_acc: array<vec4<f32>>;
// Two vec4 per cell: escapes realised so far, escapes of the current emission.
@group(0) @binding(8) var<storage, read_write> esc: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> p_out: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> a_out: array<vec4<f32>>;

// Four vec4 per cell in `emit`: front, side, back fractions and path length.
fn store_emit(c: u32, lobe: Lobe, path: vec3<f32>) {
    emit[4u * c] = vec4<f32>(lobe.front, 0.0);
    emit[4u * c + 1u] = vec4<f32>(lobe.side, 0.0);
    emit[4u * c + 2u] = vec4<f32>(lobe.back, 0.0);
    emit[4u * c + 3u] = vec4<f32>(path, 0.0);
}

struct Gathered {
    l: vec3<f32>,
    la: vec3<f32>,
};

// What cell `src` sends through `slot` (0 front, 1 side, 2 back) reaches a cell of
// coefficients sa_d, ss_d: absorption-only transmittance over the path, the anisotropy decayed
// by |g|^(s path) and multiplied by `sign` (-1 through the radial grid's centre).
fn add_from(acc: ptr<function, Gathered>, src: u32, slot: u32, sign: f32, sa_d: vec3<f32>, ss_d: vec3<f32>) {
    let ps = p_in[src].xyz;
    if (all(ps == vec3<f32>(0.0))) {
        return;
    }
    let frac = emit[4u * src + slot].xyz;
    let path = emit[4u * src + 3u].xyz;
    let sa = 0.5 * (sigma_a[src].xyz + sa_d);
    let ss = 0.5 * (sigma_s[src].xyz + ss_d);
    let dl = ps * frac * exp(-sa * path);
    let da = a_in[src].xyz * exp(ss * path * params.consts.z);
    (*acc).l += dl;
    (*acc).la += dl * da * sign;
}

fn store_gathered(dst: u32, acc: Gathered) {
    p_out[dst] = vec4<f32>(acc.l, 0.0);
    a_out[dst] = vec4<f32>(select(vec3<f32>(0.0), acc.la / max(acc.l, vec3<f32>(1e-30)), acc.l > vec3<f32>(1e-30)), 0.0);
}
