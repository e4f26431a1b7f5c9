// S towards the camera from photon-grid's cache (volscatter-core solvers/photon_grid/
// reconstruct.rs `scattering_towards`), one invocation per output voxel of a slab of planes:
// at the voxel's world point x with density rho > 0, S = sigma_s(rho) sum over the lobes of
// phi p_HG(mu, g g'), each lobe upsampled either trilinearly (cache.rs / reconstruct.rs
// `Tallies::lobe`: mass-weighted, the ratios after) or by the paper's physically based filter
// (upsample.rs `Upsampler::lobe`), same cells, same order of summation, same guards as the CPU.
// affine, the lattice helpers, density_at (the shared bricked density) and hg come from the
// preludes (shaders/src/wgsl).
//
// Where f32 departs from the CPU: f_exp, which the CPU evaluates in f64, is written here in a
// form without its two cancellations (1 - e^-x and 1 - e^-a (1 + a) by their series where they
// are small); Rust's round (half away from zero) is spelled out, WGSL's rounds half to even.

struct Params {
    out_i2w: array<vec4<f32>, 3>,     // output index -> world
    density_w2i: array<vec4<f32>, 3>,
    density_brick_min: vec4<i32>,
    density_brick_dims: vec4<u32>,
    cell_w2i: array<vec4<f32>, 3>,    // world -> cache cell index
    cell_i2w: array<vec4<f32>, 3>,    // cache cell index -> world
    cell_dims: vec4<i32>,             // xyz, w = cells per lobe
    out_dims: vec4<u32>,              // nx, ny, the slab's first plane, lobes
    camera: vec4<f32>,                // xyz, w = the medium's g
    sigma_s: vec4<f32>,               // albedo * density_scale, w = its channels' mean (Upsampler)
    physical: vec4<f32>,              // 1 / max density, r, -, 1: physical upsampling, 0: trilinear
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
// Per lobe, per cell, three vec4: (flux RGB, weight), (moment XYZ, order sum),
// (mass, the cell's mean density over the grid's maximum (Upsampler.cell_density), -, -).
@group(0) @binding(2) var<storage, read> cells: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out_s: array<vec4<f32>>;

// reconstruct.rs `Lobe`, without the deposits (S does not read them).
struct CacheLobe {
    fluence: vec3<f32>,
    g: f32,
    direction: vec3<f32>,
    order: f32,
};

fn cell(lobe: u32, i: u32, k: u32) -> vec4<f32> {
    return cells[(lobe * u32(params.cell_dims.w) + i) * 3u + k];
}

fn cell_index(q: vec3<i32>) -> u32 {
    let d = params.cell_dims.xyz;
    return u32(q.x + d.x * (q.y + d.y * q.z));
}

fn outside_cells(q: vec3<i32>) -> bool {
    return any(q < vec3<i32>(0)) || any(q >= params.cell_dims.xyz);
}

// The lobe from the ratios of the sums (zero fluence where there is no mass or weight).
fn lobe_from(flux: vec3<f32>, moment: vec3<f32>, weight: f32, mass: f32, order: f32) -> CacheLobe {
    var l: CacheLobe;
    if (mass <= 0.0 || weight <= 0.0) {
        return l;
    }
    let len = length(moment);
    l.fluence = flux / mass;
    l.g = min(len / weight, 0.999);
    if (len > 0.0) {
        l.direction = moment / len;
    }
    l.order = order;
    return l;
}

// cache.rs / reconstruct.rs `Tallies::lobe`: each tally trilinear between cell centres.
fn trilinear_lobe(lobe: u32, x: vec3<f32>) -> CacheLobe {
    let q = affine(params.cell_w2i, x);
    let base_f = floor(q);
    let base = vec3<i32>(base_f);
    let f = q - base_f;
    var flux = vec3<f32>(0.0);
    var moment = vec3<f32>(0.0);
    var weight = 0.0;
    var mass = 0.0;
    var order = 0.0;
    for (var c = 0; c < 8; c++) {
        let o = corner(c);
        let p = base + o;
        if (outside_cells(p)) {
            continue;
        }
        let w = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1) * select(1.0 - f.z, f.z, o.z == 1);
        let i = cell_index(p);
        let a = cell(lobe, i, 0u);
        let b = cell(lobe, i, 1u);
        flux += a.xyz * w;
        moment += b.xyz * w;
        weight += a.w * w;
        mass += cell(lobe, i, 2u).x * w;
        order += b.w * w;
    }
    return lobe_from(flux, moment, weight, mass, order / weight);
}

// 1 - e^-x for x >= 0, without the cancellation of the difference below x = 0.1 (Taylor to
// x^6: relative error under 1e-10 there; above, 6e-8 / x at most).
fn one_minus_exp_neg(x: f32) -> f32 {
    if (x < 0.1) {
        return x * (1.0 - x / 2.0 * (1.0 - x / 3.0 * (1.0 - x / 4.0 * (1.0 - x / 5.0 * (1.0 - x / 6.0)))));
    }
    return 1.0 - exp(-x);
}

// 1 - e^-a (1 + a) for a >= 1e-4: the series sum over k >= 2 of (-1)^k (k - 1) a^k / k!
// below a = 0.5 (about a^2 / 2, which the difference would lose entirely in f32 near 1e-4),
// its terms to a^12 (the rest under 1e-11 relative).
fn exp_normaliser(a: f32) -> f32 {
    if (a >= 0.5) {
        return 1.0 - exp(-a) * (1.0 + a);
    }
    var term = a;
    var sum = 0.0;
    for (var k = 2; k <= 12; k++) {
        term *= a / f32(k);
        let with_sign = select(-term, term, (k & 1) == 0);
        sum += with_sign * f32(k - 1);
    }
    return sum;
}

// upsample.rs `f_exp`: the exponential of rate lambda truncated to [0, r], renormalised.
fn f_exp(d_in: f32, lambda_in: f32, r: f32) -> f32 {
    if (!(d_in < r) || !(r > 0.0)) {
        return 0.0;
    }
    let d = max(d_in, 0.0);
    let lambda = max(lambda_in, 0.0);
    let a = lambda * r;
    if (a < 1e-4) {
        return 2.0 * (r - d) / (r * r);
    }
    // lambda (e^(-lambda d) - e^(-a)) = lambda e^(-lambda d) (1 - e^(-lambda (r - d))).
    let num = lambda * exp(-lambda * d) * one_minus_exp_neg(lambda * (r - d));
    return max(num / exp_normaliser(a), 0.0);
}

fn f_lin(d: f32) -> f32 {
    return max(1.0 - d, 0.0);
}

fn g_delta(g: f32, delta: f32) -> f32 {
    return pow(max(abs(g), 1e-3), delta);
}

// Rust's f32::round: halves away from zero.
fn round_away(v: vec3<f32>) -> vec3<f32> {
    let t = trunc(v);
    return select(t, t + sign(v), abs(v - t) >= vec3<f32>(0.5));
}

// upsample.rs `Upsampler::lobe`: the 3^3 cells around the nearest, weighted by distance and
// density difference, each neighbour's g' extrapolated by g^delta.
fn physical_lobe(lobe: u32, x: vec3<f32>, rho: f32) -> CacheLobe {
    let tri = trilinear_lobe(lobe, x);
    let density_norm = params.physical.x;
    let r = params.physical.y;
    let g = params.camera.w;
    let centre = vec3<i32>(round_away(affine(params.cell_w2i, x)));
    let dp = rho * density_norm;
    let gamma_p = tri.order;
    var flux = vec3<f32>(0.0);
    var moment = vec3<f32>(0.0);
    var weight = 0.0;
    var mass = 0.0;
    for (var c = 0; c < 27; c++) {
        let q = centre + vec3<i32>(c % 3 - 1, (c / 3) % 3 - 1, c / 9 - 1);
        if (outside_cells(q)) {
            continue;
        }
        let i = cell_index(q);
        let a = cell(lobe, i, 0u);
        let m = cell(lobe, i, 2u);
        if (m.x <= 0.0 || a.w <= 0.0) {
            continue;
        }
        let dq = m.y;
        let lambda = params.sigma_s.w * (dp + dq) * 0.5 / density_norm;
        let distance = length(affine(params.cell_i2w, vec3<f32>(q)) - x);
        let w = f_exp(distance, lambda, r) * f_lin(abs(dp - dq));
        if (w <= 0.0) {
            continue;
        }
        let b = cell(lobe, i, 1u);
        let gamma_q = b.w / a.w;
        let g_q = length(b.xyz) / a.w;
        let extrapolated = min(g_delta(g, gamma_p - gamma_q), 0.999 / max(g_q, 1e-6));
        flux += a.xyz * w;
        mass += m.x * w;
        moment += b.xyz * (extrapolated * w);
        weight += a.w * w;
    }
    if (mass <= 0.0 || weight <= 0.0) {
        return tri;
    }
    return lobe_from(flux, moment, weight, mass, gamma_p);
}

// glam's normalize_or_zero.
fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let len = length(v);
    if (len > 0.0 && len < 3.4e38) {
        return v / len;
    }
    return vec3<f32>(0.0);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let nx = params.out_dims.x;
    let ny = params.out_dims.y;
    if (gid.x >= nx || gid.y >= ny) {
        return;
    }
    let o = gid.x + nx * (gid.y + ny * gid.z);
    if (o >= arrayLength(&out_s)) {
        return;
    }
    let x = affine(params.out_i2w, vec3<f32>(f32(gid.x), f32(gid.y), f32(gid.z + params.out_dims.z)));
    let rho = density_at(x);
    if (rho <= 0.0) {
        out_s[o] = vec4<f32>(0.0);
        return;
    }
    let to_camera = normalize_or_zero(params.camera.xyz - x);
    var s = vec3<f32>(0.0);
    for (var l = 0u; l < params.out_dims.w; l++) {
        var lobe: CacheLobe;
        if (params.physical.w != 0.0) {
            lobe = physical_lobe(l, x, rho);
        } else {
            lobe = trilinear_lobe(l, x);
        }
        s += lobe.fluence * hg(dot(lobe.direction, to_camera), params.camera.w * lobe.g);
    }
    out_s[o] = vec4<f32>(params.sigma_s.xyz * rho * s, 0.0);
}
