// The compositor's ray march (volscatter-core `compositor::march`), one invocation per pixel:
// L = sum over steps of T * S(x) * (1 - exp(-sigma_t h)) / sigma_t, T *= exp(-sigma_t h),
// plus the same for the single-scattering grid S1, and the environment through T.
// Layout of `Params` is mirrored by `CompositeParams` in mod.rs (checked there).
// density_at, affine, the trilinear helpers, ray_box and PI come from the preludes
// (shaders/src/wgsl), prepended.

struct Params {
    density_w2i: array<vec4<f32>, 3>,  // world -> density index, rows of a 3x4 affine
    s_w2i: array<vec4<f32>, 3>,        // world -> S grid index
    s1_w2i: array<vec4<f32>, 3>,       // world -> S1 grid index
    density_brick_min: vec4<i32>,      // wgsl/density.wgsl
    density_brick_dims: vec4<u32>,
    s_dims: vec4<u32>,
    s1_dims: vec4<u32>,
    density_scale: vec4<f32>,
    bounds_lo: vec4<f32>,
    bounds_hi: vec4<f32>,
    cam_pos: vec4<f32>,
    cam_fwd: vec4<f32>,
    cam_right: vec4<f32>,
    cam_up: vec4<f32>,
    env_color: vec4<f32>,              // w = 1 when there is an environment
    image: vec4<u32>,                  // width, height, subpixels, flags (1: env map, 2: transparent)
    env_dims: vec4<u32>,
    misc: vec4<f32>,                   // tan(fov/2), march step, -, -
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> density: array<u32>;
@group(0) @binding(2) var<storage, read> s_grid: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> s1_grid: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> env_map: array<vec4<f32>>;
// Three vec4 per pixel: rgba, single scattering, background.
@group(0) @binding(5) var<storage, read_write> out_pixels: array<vec4<f32>>;

fn grid_at(which: u32, x: vec3<f32>) -> vec3<f32> {
    var p: vec3<f32>;
    var dims: vec3<i32>;
    if (which == 0u) {
        p = affine(params.s_w2i, x);
        dims = vec3<i32>(params.s_dims.xyz);
    } else {
        p = affine(params.s1_w2i, x);
        dims = vec3<i32>(params.s1_dims.xyz);
    }
    // ScatteringGrid::sample_index: zero outside [0, dims - 1], corners clamped into the grid.
    if (!inside(p, vec3<f32>(0.0), vec3<f32>(dims - vec3<i32>(1)))) {
        return vec3<f32>(0.0);
    }
    let l = lattice(p);
    var c: array<vec3<f32>, 8>;
    for (var k = 0; k < 8; k++) {
        let idx = clamped_index(l.base + corner(k), dims);
        if (which == 0u) {
            c[k] = s_grid[idx].xyz;
        } else {
            c[k] = s1_grid[idx].xyz;
        }
    }
    return trilinear3(c, l.t);
}

fn env_radiance(d: vec3<f32>) -> vec3<f32> {
    if ((params.image.w & 1u) == 0u) {
        return params.env_color.xyz;
    }
    var u = 0.5 - atan2(d.y, d.x) / (2.0 * PI);
    u = u - floor(u);
    let v = clamp(0.5 + asin(clamp(d.z, -1.0, 1.0)) / PI, 0.0, 1.0);
    let w = params.env_dims.x;
    let h = params.env_dims.y;
    let x = min(u32(u * f32(w)), w - 1u);
    let row = min(u32((1.0 - v) * f32(h)), h - 1u);
    return env_map[row * w + x].xyz * params.env_color.xyz;
}

fn ray_dir(px: f32, py: f32) -> vec3<f32> {
    let w = f32(params.image.x);
    let h = f32(params.image.y);
    let th = params.misc.x;
    let sx = (2.0 * px / w - 1.0) * th;
    let sy = (1.0 - 2.0 * py / h) * th * h / w;
    return normalize(params.cam_fwd.xyz + params.cam_right.xyz * sx + params.cam_up.xyz * sy);
}

struct March {
    l: vec3<f32>,
    l1: vec3<f32>,
    tr: vec3<f32>,
};

fn march(o: vec3<f32>, d: vec3<f32>) -> March {
    var r: March;
    r.l = vec3<f32>(0.0);
    r.l1 = vec3<f32>(0.0);
    r.tr = vec3<f32>(1.0);
    let span = ray_box(o, d, params.bounds_lo.xyz, params.bounds_hi.xyz);
    let t0 = span.x;
    let t1 = span.y;
    if (!(t0 < t1)) {
        return r;
    }
    let n = clamp(u32(ceil((t1 - t0) / params.misc.y)), 1u, 8192u);
    let h = (t1 - t0) / f32(n);
    for (var i = 0u; i < n; i++) {
        let x = o + d * (t0 + (f32(i) + 0.5) * h);
        let sigma_t = params.density_scale.xyz * density_at(x);
        let seg = exp(-sigma_t * h);
        // (1 - e^{-x}) / sigma, by its series for small x = sigma h (as on the CPU).
        let od = sigma_t * h;
        let series = h * (vec3<f32>(1.0) - od * 0.5 + od * od / 6.0);
        let weight = select(series, (vec3<f32>(1.0) - seg) / sigma_t, od > vec3<f32>(0.01));
        r.l += r.tr * weight * grid_at(0u, x);
        r.l1 += r.tr * weight * grid_at(1u, x);
        r.tr *= seg;
        if (max(max(r.tr.x, r.tr.y), r.tr.z) < 1e-5) {
            r.tr = vec3<f32>(0.0);
            break;
        }
    }
    return r;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.image.x;
    let h = params.image.y;
    if (gid.x >= w || gid.y >= h) {
        return;
    }
    let k = params.image.z;
    var l = vec3<f32>(0.0);
    var l1 = vec3<f32>(0.0);
    var bg = vec3<f32>(0.0);
    var tsum = vec3<f32>(0.0);
    for (var sy = 0u; sy < k; sy++) {
        for (var sx = 0u; sx < k; sx++) {
            let d = ray_dir(f32(gid.x) + (f32(sx) + 0.5) / f32(k), f32(gid.y) + (f32(sy) + 0.5) / f32(k));
            let m = march(params.cam_pos.xyz, d);
            l += m.l;
            l1 += m.l1;
            tsum += m.tr;
            if (params.env_color.w > 0.0) {
                bg += m.tr * env_radiance(d);
            }
        }
    }
    let inv = 1.0 / f32(k * k);
    l *= inv;
    l1 *= inv;
    bg *= inv;
    let tr = tsum * inv;
    let alpha = clamp(1.0 - dot(tr, vec3<f32>(1.0 / 3.0)), 0.0, 1.0);
    var rgb = l;
    if ((params.image.w & 2u) == 0u) {
        rgb += bg;
    }
    let idx = (gid.y * w + gid.x) * 3u;
    out_pixels[idx] = vec4<f32>(rgb, alpha);
    out_pixels[idx + 1u] = vec4<f32>(l1, 0.0);
    out_pixels[idx + 2u] = vec4<f32>(bg, 0.0);
}
