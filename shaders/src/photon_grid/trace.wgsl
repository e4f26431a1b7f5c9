// photon-grid's tracing (volscatter-core solvers/photon_grid/trace.rs `Tracer::photon`): one
// invocation per photon, from its ray (drawn on the CPU by the shared LightSampler) to its
// end: Woodcock / spectral tracking with a deposit into the cache at every tentative
// collision, HG scattering, the transmittance cutoff and the similarity switch.
//
// Tracking walks the CPU's majorant grids (full and reduced medium) by the same DDA
// (medium/majorant.rs `traverse`, in the density's index space). Departures from the CPU,
// each for the GPU:
// - random numbers from xoshiro128** seeded per photon (hash of seed, generation, photon
//   index): the CPU's batches draw from one PCG32 stream in photon order, which invocations
//   running side by side cannot share;
// - deposits are summed as 64-bit fixed-point integers with 32-bit atomics (low word, then the
//   carry into the high word): integer sums do not depend on the order in which invocations
//   add, so a generation's tallies are the same on every run (f32 atomics would not be).
// - a workgroup pre-sums its 64 photons' deposits in workgroup memory (the issue's "atomics
//   into workgroup memory, then a reduction") before adding them to the cache in device
//   memory. The cache (cells x 2 lobes x 9 sums of 8 bytes) does not fit workgroup memory
//   (WebGPU's guaranteed 16 KiB: Fig. 12's smallest cache, 315 cells, takes 45 KiB; the
//   default ~1 MiB), so the workgroup keeps a hash table of WG_SLOTS (lobe, cell) entries:
//   a deposit whose cell has a slot (claimed by compare-exchange on first use, WG_PROBES
//   linear probes) adds there, any other goes to device memory directly; after a barrier the
//   workgroup adds each slot's sums to the cache once. The energy sums (the same 22 words for
//   every photon, the hottest contention) are pre-summed the same way. Sums of 64-bit
//   integers modulo 2^64 do not depend on grouping, so the cache is bit for bit the one
//   without the pre-sum (`params.first.y` != 0 turns it off; tests.rs compares the two).
// affine, density_at, ray_box come from the preludes (shaders/src/wgsl).

struct Phase {
    scale: vec4<f32>,   // density_scale (RGB), w: unused
    albedo: vec4<f32>,  // albedo (RGB), w: HG g
};

struct Params {
    density_w2i: array<vec4<f32>, 3>,
    density_brick_min: vec4<i32>,
    density_brick_dims: vec4<u32>,
    cell_w2i: array<vec4<f32>, 3>,
    cell_dims: vec4<u32>,   // cache cells nx, ny, nz; w: cells in all
    box_lo: vec4<f32>,      // the medium's world box; w: cutoff
    box_hi: vec4<f32>,
    full: Phase,
    reduced: Phase,
    units: vec4<f32>,       // 1 / unit of: deposits (flux, moment, weight), order sums, energy
    flags: vec4<u32>,       // order of the similarity switch (0: none), split order, deposit unscattered, photons in this dispatch
    seeds: vec4<u32>,       // seed (lo, hi), generation (lo, hi)
    first: vec4<u32>,       // index of this dispatch's first photon in its generation; y: 1 = no workgroup pre-sum
    maj_origin: vec4<f32>,  // majorant grid's minimum corner (index space), w: cell edge (voxels)
    maj_dims: vec4<i32>,    // its cells per axis, w: where the reduced medium's values start
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
// Three vec4 per photon: origin, direction, power (RGB, already / photon count).
@group(0) @binding(2) var<storage, read> rays: array<vec4<f32>>;
// Per lobe and cell, CELL_WORDS words: 9 sums as (low, high) words of 64-bit integers; then
// the energy's: escaped, absorbed, cut (RGB), scatterings, switched as 64-bit pairs.
@group(0) @binding(3) var<storage, read_write> sums: array<atomic<u32>>;
// The full medium's majorant grid values, then the reduced medium's (same cells).
@group(0) @binding(4) var<storage, read> majorant: array<f32>;

const CELL_WORDS: u32 = 18u;
const MAX_TENTATIVE_STEPS: u32 = 4194304u; // medium/tracking.rs
const TWO_PI: f32 = 6.28318530717959;

// ---- random numbers: xoshiro128** (Blackman, Vigna), seeded by hashing ----
var<private> rng_s: vec4<u32>;

fn fmix32(x0: u32) -> u32 {
    var x = x0;
    x ^= x >> 16u;
    x *= 0x85ebca6bu;
    x ^= x >> 13u;
    x *= 0xc2b2ae35u;
    x ^= x >> 16u;
    return x;
}

fn rotl(x: u32, k: u32) -> u32 {
    return (x << k) | (x >> (32u - k));
}

fn rng_seed(photon: u32) {
    let a = fmix32(params.seeds.x ^ fmix32(params.seeds.y + 0x9e3779b9u));
    let b = fmix32(params.seeds.z ^ fmix32(params.seeds.w + 0x7f4a7c15u));
    let p = fmix32(photon + 0x632be5abu);
    rng_s = vec4<u32>(fmix32(a ^ p), fmix32(b ^ p ^ 0x1b873593u), fmix32(a ^ b ^ p ^ 0xe6546b64u), fmix32(p ^ 0xcc9e2d51u) | 1u);
}

fn rng_u32() -> u32 {
    let result = rotl(rng_s.y * 5u, 7u) * 9u;
    let t = rng_s.y << 9u;
    rng_s.z ^= rng_s.x;
    rng_s.w ^= rng_s.y;
    rng_s.y ^= rng_s.z;
    rng_s.x ^= rng_s.w;
    rng_s.z ^= t;
    rng_s.w = rotl(rng_s.w, 11u);
    return result;
}

// Uniform in [0, 1) with 24 bits, as rng.rs.
fn rng_f32() -> f32 {
    return f32(rng_u32() >> 8u) * (1.0 / 16777216.0);
}

// ---- 64-bit fixed-point sums with 32-bit atomics ----

// x (already in units) rounded to a 64-bit two's complement integer (low, high). |x| < 2^62.
fn to_fixed(x: f32) -> vec2<u32> {
    let a = min(abs(x), 4.6e18);
    let hi_f = floor(a * 2.3283064365386963e-10);
    // Exact: a and hi_f 2^32 are both multiples of a's last bit.
    let lo_f = round(a - hi_f * 4294967296.0);
    var lo = u32(lo_f);
    var hi = u32(hi_f);
    if (x < 0.0) {
        lo = ~lo + 1u;
        hi = ~hi + select(0u, 1u, lo == 0u);
    }
    return vec2<u32>(lo, hi);
}

// What to add to the high word after adding v.x to a low word that held `old`: v.y, plus
// one where the low word wrapped.
fn high_part(old: u32, v: vec2<u32>) -> u32 {
    return v.y + select(0u, 1u, old + v.x < old);
}
// Adds the 64-bit integer v = (low, high) to the sum at words i, i + 1 of the cache.
fn add_pair(i: u32, v: vec2<u32>) {
    if (any(v != vec2<u32>(0u))) {
        let h = high_part(atomicAdd(&sums[i], v.x), v);
        if (h != 0u) {
            atomicAdd(&sums[i + 1u], h);
        }
    }
}
// ---- the workgroup's pre-sum (module doc) ----
const WG_SLOTS: u32 = 160u;
const WG_PROBES: u32 = 4u;
const WG_ENERGY_WORDS: u32 = 22u;
// Slot keys: 0 free, else 1 + lobe x cells + cell.
var<workgroup> wg_keys: array<atomic<u32>, WG_SLOTS>;
// Per slot CELL_WORDS words as the cache's, then the energy sums (as the cache's, from word 0).
var<workgroup> wg_sums: array<atomic<u32>, 2902>; // WG_SLOTS * CELL_WORDS + WG_ENERGY_WORDS
// add_pair into workgroup memory (its twin: a WGSL function's atomics live in one address
// space).
fn wg_add_pair(i: u32, v: vec2<u32>) {
    if (any(v != vec2<u32>(0u))) {
        let h = high_part(atomicAdd(&wg_sums[i], v.x), v);
        if (h != 0u) {
            atomicAdd(&wg_sums[i + 1u], h);
        }
    }
}
fn presum() -> bool {
    return params.first.y == 0u;
}
// The slot holding `key` (claimed if free), or -1: the table is off, or the probed slots are
// taken by other cells (or a weak exchange failed spuriously: the deposit then goes to device
// memory, which is exact as well).
fn wg_slot(key: u32) -> i32 {
    if (!presum()) {
        return -1;
    }
    let h = fmix32(key) % WG_SLOTS;
    for (var k = 0u; k < WG_PROBES; k++) {
        let s = (h + k) % WG_SLOTS;
        let r = atomicCompareExchangeWeak(&wg_keys[s], 0u, key);
        if (r.exchanged || r.old_value == key) {
            return i32(s);
        }
    }
    return -1;
}
// Adds v to energy sum word w (energy_word's numbering), through the workgroup when on.
fn energy_pair(w: u32, v: vec2<u32>) {
    if (presum()) {
        wg_add_pair(WG_SLOTS * CELL_WORDS + w, v);
    } else {
        add_pair(energy_word(w), v);
    }
}
// The energy sums' first word: after both lobes' cells.
fn energy_word(w: u32) -> u32 {
    return 2u * params.cell_dims.w * CELL_WORDS + w;
}

fn energy_add3(q: u32, v: vec3<f32>) {
    let s = v * params.units.z;
    energy_pair(6u * q, to_fixed(s.x));
    energy_pair(6u * q + 2u, to_fixed(s.y));
    energy_pair(6u * q + 4u, to_fixed(s.z));
}

// cache.rs `Cache::cell_of`: the cell whose centre is nearest, or none.
fn cell_of(x: vec3<f32>) -> i32 {
    let p = round(affine(params.cell_w2i, x));
    let d = vec3<f32>(params.cell_dims.xyz);
    if (any(p < vec3<f32>(0.0)) || any(p >= d)) {
        return -1;
    }
    let c = vec3<u32>(p);
    return i32(c.x + params.cell_dims.x * (c.y + params.cell_dims.y * c.z));
}

// cache.rs `Cache::deposit`: RGB flux f, scalar weight (mean of f), moment, order, count.
fn deposit(x: vec3<f32>, f: vec3<f32>, dir: vec3<f32>, order: u32, lobe: u32) {
    let cell = cell_of(x);
    if (cell < 0) {
        return;
    }
    let key = lobe * params.cell_dims.w + u32(cell);
    let w = (f.x + f.y + f.z) / 3.0;
    let k = params.units.x;
    var v: array<vec2<u32>, 9>;
    v[0] = to_fixed(f.x * k);
    v[1] = to_fixed(f.y * k);
    v[2] = to_fixed(f.z * k);
    v[3] = to_fixed(dir.x * w * k);
    v[4] = to_fixed(dir.y * w * k);
    v[5] = to_fixed(dir.z * w * k);
    v[6] = to_fixed(w * k);
    v[7] = to_fixed(w * f32(order) * params.units.y);
    v[8] = vec2<u32>(1u, 0u);
    let slot = wg_slot(key + 1u);
    if (slot >= 0) {
        let base = u32(slot) * CELL_WORDS;
        for (var i = 0u; i < 9u; i++) {
            wg_add_pair(base + 2u * i, v[i]);
        }
    } else {
        let base = key * CELL_WORDS;
        for (var i = 0u; i < 9u; i++) {
            add_pair(base + 2u * i, v[i]);
        }
    }
}
// ---- directions (sampling.rs, phase.rs) ----

fn uniform_sphere(u0: f32, u1: f32) -> vec3<f32> {
    let z = 1.0 - 2.0 * u0;
    let r = sqrt(max(1.0 - z * z, 0.0));
    let phi = TWO_PI * u1;
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

fn hg_sample(dir_in: vec3<f32>, g: f32, u0: f32, u1: f32) -> vec3<f32> {
    var cos_theta = 1.0 - 2.0 * u0;
    if (abs(g) >= 1e-3) {
        let s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u0);
        cos_theta = clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
    }
    let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    let phi = TWO_PI * u1;
    // sampling.rs orthonormal_basis
    let n = dir_in;
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bb = vec3<f32>(b, sign + n.y * n.y * a, -n.y);
    return normalize(t * (sin_theta * cos(phi)) + bb * (sin_theta * sin(phi)) + dir_in * cos_theta);
}

fn max3(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

// ---- the majorant grid's DDA (medium/majorant.rs `traverse`), one segment per call ----
const BIG: f32 = 3.4e38;
var<private> dda_t: f32;
var<private> dda_end: f32;
var<private> dda_c: vec3<i32>;
var<private> dda_step: vec3<i32>;
var<private> dda_next: vec3<f32>;
var<private> dda_delta: vec3<f32>;
var<private> dda_done: bool;
var<private> dda_values: i32;

// Starts the walk of the index-space ray o + t di (t >= 0) over the grid whose values start at
// `values`; dda_done when it misses.
fn dda_start(o: vec3<f32>, di: vec3<f32>, values: i32) {
    let dims = params.maj_dims.xyz;
    let cell = params.maj_origin.w;
    let gmin = params.maj_origin.xyz;
    let gmax = gmin + vec3<f32>(dims) * cell;
    dda_values = values;
    dda_done = any(dims <= vec3<i32>(0));
    let inv = 1.0 / di;
    let ta = (gmin - o) * inv;
    let tb = (gmax - o) * inv;
    // A NaN slab (a ray parallel to and on a boundary) does not constrain.
    let nan = (ta != ta) | (tb != tb);
    let tnear = select(min(ta, tb), vec3<f32>(-BIG), nan);
    let tfar = select(max(ta, tb), vec3<f32>(BIG), nan);
    dda_t = max(0.0, max3(tnear));
    dda_end = min(tfar.x, min(tfar.y, tfar.z));
    if (!(dda_t < dda_end)) {
        dda_done = true;
        return;
    }
    let p = (o + di * dda_t - gmin) / cell;
    dda_c = clamp(vec3<i32>(floor(p)), vec3<i32>(0), dims - vec3<i32>(1));
    dda_step = select(vec3<i32>(-1), vec3<i32>(1), di > vec3<f32>(0.0));
    let edge = gmin + vec3<f32>(dda_c + select(vec3<i32>(0), vec3<i32>(1), di > vec3<f32>(0.0))) * cell;
    dda_next = select((edge - o) / di, vec3<f32>(BIG), di == vec3<f32>(0.0));
    dda_delta = abs(vec3<f32>(cell) * inv);
}

// The next segment (t0, t1, majorant); advances the walk, setting dda_done after the last.
// Use it only if t1 > t0.
fn dda_segment() -> vec3<f32> {
    var axis = 2;
    if (dda_next.x < dda_next.y && dda_next.x < dda_next.z) {
        axis = 0;
    } else if (dda_next.y < dda_next.z) {
        axis = 1;
    }
    let t1 = min(dda_next[axis], dda_end);
    let dims = params.maj_dims.xyz;
    let idx = dda_c.x + dims.x * (dda_c.y + dims.y * dda_c.z);
    let seg = vec3<f32>(dda_t, t1, majorant[dda_values + idx]);
    if (dda_next[axis] >= dda_end) {
        dda_done = true;
        return seg;
    }
    dda_t = t1;
    dda_c[axis] += dda_step[axis];
    if (dda_c[axis] < 0 || dda_c[axis] >= dims[axis]) {
        dda_done = true;
        return seg;
    }
    dda_next[axis] += dda_delta[axis];
    return seg;
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(num_workgroups) groups: vec3<u32>) {
    // Clear the workgroup's table (explicitly: not every backend zeroes workgroup memory).
    for (var i = lid; i < WG_SLOTS; i += 64u) {
        atomicStore(&wg_keys[i], 0u);
    }
    for (var i = lid; i < WG_SLOTS * CELL_WORDS + WG_ENERGY_WORDS; i += 64u) {
        atomicStore(&wg_sums[i], 0u);
    }
    workgroupBarrier();
    let id = gid.x + gid.y * groups.x * 64u;
    if (id < params.flags.w) {
        trace_photon(id);
    }
    workgroupBarrier();
    // The reduction: each slot's sums (and the energy sums) into the cache, once.
    for (var s = lid; s < WG_SLOTS; s += 64u) {
        let key = atomicLoad(&wg_keys[s]);
        if (key != 0u) {
            for (var i = 0u; i < CELL_WORDS; i += 2u) {
                let w = s * CELL_WORDS + i;
                add_pair((key - 1u) * CELL_WORDS + i, vec2<u32>(atomicLoad(&wg_sums[w]), atomicLoad(&wg_sums[w + 1u])));
            }
        }
    }
    for (var i = 2u * lid; i < WG_ENERGY_WORDS; i += 128u) {
        let w = WG_SLOTS * CELL_WORDS + i;
        add_pair(energy_word(i), vec2<u32>(atomicLoad(&wg_sums[w]), atomicLoad(&wg_sums[w + 1u])));
    }
}

// One photon from its ray (`id` in this dispatch) to its end.
fn trace_photon(id: u32) {
    rng_seed(params.first.x + id);
    var x = rays[3u * id].xyz;
    var d = rays[3u * id + 1u].xyz;
    let power = rays[3u * id + 2u].xyz;
    var beta = vec3<f32>(1.0);
    var order = 0u;
    var reduced = false;
    let lo = params.box_lo.xyz;
    let hi = params.box_hi.xyz;
    let cutoff = params.box_lo.w;
    let switch_at = params.flags.x;
    loop {
        let span = ray_box(x, d, lo, hi);
        if (!(span.x < span.y)) {
            break;
        }
        var phase = params.full;
        if (reduced) {
            phase = params.reduced;
        }
        let inv_scale = 1.0 / max(max3(phase.scale.xyz), 1e-30);
        let deposits = order > 0u || params.flags.z != 0u;
        let lobe = select(0u, 1u, order >= params.flags.y);
        // Free flight (tracking.rs `sample_free_flight_visiting`): exponential steps at each
        // majorant cell's rate, restarted at every cell's entry (memoryless).
        let w2i = params.density_w2i;
        let di = vec3<f32>(dot(w2i[0].xyz, d), dot(w2i[1].xyz, d), dot(w2i[2].xyz, d));
        dda_start(affine(w2i, x), di, select(0, params.maj_dims.w, reduced));
        var t = 0.0;
        var hit = false;
        var steps = 0u;
        while (!dda_done && !hit) {
            let seg = dda_segment();
            let m = seg.z;
            if (!(seg.y > seg.x) || m <= 0.0) {
                continue;
            }
            t = seg.x;
            loop {
                let step = -log(1.0 - rng_f32()) / m;
                let next = t + step;
                steps += 1u;
                // Float32 running out, or too many steps: opaque here (as on the CPU).
                if ((step > 0.0 && next <= t) || steps > MAX_TENTATIVE_STEPS) {
                    hit = true;
                    break;
                }
                t = next;
                if (t >= seg.y) {
                    break;
                }
                let p = x + d * t;
                let rho = density_at(p);
                let sigma_t = phase.scale.xyz * rho;
                if (rho > 0.0 && deposits) {
                    // rho from its largest channel, as trace.rs `track`.
                    deposit(p, power * beta * (max3(sigma_t) * inv_scale / m), d, order, lobe);
                }
                let sigma_n = max(vec3<f32>(m) - sigma_t, vec3<f32>(0.0));
                let p_real_w = max3(beta * sigma_t);
                let p_null_w = max3(beta * sigma_n);
                let total = p_real_w + p_null_w;
                if (total <= 0.0) {
                    continue;
                }
                let p_real = p_real_w / total;
                if (rng_f32() < p_real) {
                    beta *= sigma_t / (m * p_real);
                    hit = true;
                    break;
                }
                beta *= sigma_n / (m * (1.0 - p_real));
            }
        }
        if (!hit) {
            break;
        }
        // Real collision: scatter with the albedo, the rest is absorbed.
        x += d * t;
        var albedo = vec3<f32>(1.0);
        if (density_at(x) > 0.0) {
            albedo = phase.albedo.xyz;
        }
        energy_add3(1u, power * beta * (vec3<f32>(1.0) - albedo));
        beta *= albedo;
        order += 1u;
        energy_pair(18u, vec2<u32>(1u, 0u));
        if (max3(beta) < cutoff || max3(beta) <= 0.0) {
            energy_add3(2u, power * beta);
            return;
        }
        if (switch_at > 0u && order == switch_at && !reduced) {
            reduced = true;
            energy_pair(20u, vec2<u32>(1u, 0u));
        }
        let g = select(params.full.albedo.w, params.reduced.albedo.w, reduced);
        let u0 = rng_f32();
        let u1 = rng_f32();
        if (g == 0.0) {
            d = uniform_sphere(u0, u1);
        } else {
            d = hg_sample(d, g, u0, u1);
        }
    }
    energy_add3(0u, power * beta);
}
