// lpm's propagate step (volscatter-core lpm/propagate.rs, paper 05 Eq. 3): one workgroup per
// tile of 64 rays and direction of one face (dispatch [tiles, p, 1]); each invocation marches
// one ray through the slab's layers w0..w1, plane by plane, writing the ray's mean radiance in
// each cell to T. The CPU shifts the whole map between layers; here a ray follows its own
// position instead, start + round(a w) (the host's table `offsets`, Rust's rounding), and
// re-enters with the boundary radiance when it crosses a side (the wrap-around, Fig. 2), which
// visits the same cells with the same radiance. Rays never share a cell within a layer: no
// atomics. The rays leaving the slab go to `map_out` (a second buffer: another ray of the
// same direction may still read its start in `map_in`).

struct Dir {
    boundary: vec4<f32>,  // radiance entering through the sides, rgb
    dl: f32,              // path length in a cell, h sqrt(1 + a^2 + b^2), computed on the host
    storage: u32,         // storage bin of U this direction reads
    pad0: u32,
    pad1: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> dirs: array<Dir>;
@group(0) @binding(2) var<storage, read> offsets: array<vec2<i32>>;
@group(0) @binding(3) var<storage, read> sigma: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> u_in: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> map_in: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> map_out: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> t_out: array<vec4<f32>>;

struct Segment {
    out: vec3<f32>,
    mean: vec3<f32>,
};

// propagate.rs `segment`, term for term (same order of operations).
fn segment(l_in: vec3<f32>, q: vec3<f32>, sigma_t: vec3<f32>, dl: f32) -> Segment {
    let od = sigma_t * dl;
    let e = exp(-od);
    let thick = od > vec3<f32>(1e-3);
    let safe = max(sigma_t, vec3<f32>(1e-30));
    let one = vec3<f32>(1.0);
    let f1 = select(vec3<f32>(dl) * (one - od * 0.5 + od * od / 6.0), (one - e) / safe, thick);
    let f2 = select(vec3<f32>(dl * dl) * (vec3<f32>(0.5) - od / 6.0 + od * od / 24.0), (vec3<f32>(dl) - f1) / safe, thick);
    return Segment(l_in * e + q * f1, (l_in * f1 + q * f2) / dl);
}

// floor(a / b) for b > 0.
fn floor_div(a: i32, b: i32) -> i32 {
    return select(a / b, (a - b + 1) / b, a < 0);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let map_len = params.map.z;
    let t = gid.x;
    if (t >= map_len) {
        return;
    }
    let li = gid.y;
    let gi = params.dirs.y + li;
    let dir = dirs[gi];
    let n = vec2<i32>(i32(params.map.x), i32(params.map.y));
    let w0 = params.sweep.x;
    let row = gi * params.dirs.w;
    // The ray starts in map cell t: at layer 0 with the boundary radiance, else as it left
    // layer w0 - 1.
    var l = dir.boundary.xyz;
    var base = offsets[row];
    if (w0 > 0u) {
        l = map_in[li * map_len + t].xyz;
        base = offsets[row + w0 - 1u];
    }
    let start = vec2<i32>(i32(t % params.map.x), i32(t / params.map.x));
    var period = vec2<i32>(0, 0);
    var cell = start;
    for (var w = w0; w < params.sweep.y; w++) {
        let p = start + offsets[row + w] - base;
        let q = vec2<i32>(floor_div(p.x, n.x), floor_div(p.y, n.y));
        if (any(q != period)) {
            l = dir.boundary.xyz;
            period = q;
        }
        cell = p - q * n;
        let k = (w - w0) * map_len + u32(cell.y) * params.map.x + u32(cell.x);
        let s = segment(l, u_in[k * params.sweep.w + dir.storage].xyz, sigma[k].xyz, dir.dl);
        l = s.out;
        t_out[li * params.map.w + k] = vec4<f32>(s.mean, 0.0);
    }
    map_out[li * map_len + u32(cell.y) * params.map.x + u32(cell.x)] = vec4<f32>(l, 0.0);
}
