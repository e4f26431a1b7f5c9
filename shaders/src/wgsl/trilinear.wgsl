// Prelude: volscatter-core medium/trilinear.rs. A kernel fetches the 8 corners of `lattice(p)`
// (corner k at base + corner(k), x fastest) with its own rule for outside points, and combines
// them with trilinear1 / trilinear3: x first, then y, then z, each lerp a (1 - t) + b t as on
// the CPU, so both round alike.

// Coordinates at or beyond 2^30 (and NaN) read zero, as on the CPU (trilinear::MAX_COORD).
const LATTICE_MAX: f32 = 1073741824.0;

struct Lattice {
    base: vec3<i32>,
    t: vec3<f32>,
    ok: bool,
};

fn lattice(p: vec3<f32>) -> Lattice {
    var l: Lattice;
    l.ok = all(abs(p) < vec3<f32>(LATTICE_MAX));
    let f = floor(select(vec3<f32>(0.0), p, l.ok));
    l.base = vec3<i32>(f);
    l.t = p - f;
    return l;
}

fn corner(k: i32) -> vec3<i32> {
    return vec3<i32>(k & 1, (k >> 1u) & 1, (k >> 2u) & 1);
}

fn lerp1(a: f32, b: f32, t: f32) -> f32 {
    return a * (1.0 - t) + b * t;
}

fn lerp3(a: vec3<f32>, b: vec3<f32>, t: f32) -> vec3<f32> {
    return a * (1.0 - t) + b * t;
}

fn trilinear1(c: array<f32, 8>, t: vec3<f32>) -> f32 {
    let c0 = lerp1(lerp1(c[0], c[1], t.x), lerp1(c[2], c[3], t.x), t.y);
    let c1 = lerp1(lerp1(c[4], c[5], t.x), lerp1(c[6], c[7], t.x), t.y);
    return lerp1(c0, c1, t.z);
}

fn trilinear3(c: array<vec3<f32>, 8>, t: vec3<f32>) -> vec3<f32> {
    let c0 = lerp3(lerp3(c[0], c[1], t.x), lerp3(c[2], c[3], t.x), t.y);
    let c1 = lerp3(lerp3(c[4], c[5], t.x), lerp3(c[6], c[7], t.x), t.y);
    return lerp3(c0, c1, t.z);
}

// trilinear::inside: p in the box [lo, hi] (false for NaN).
fn inside(p: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> bool {
    return all(p >= lo) && all(p <= hi);
}

// trilinear::clamped_index: lattice point c clamped into a dense x-fastest array of `dims`.
fn clamped_index(c: vec3<i32>, dims: vec3<i32>) -> u32 {
    let k = clamp(c, vec3<i32>(0), dims - vec3<i32>(1));
    return u32(k.x + dims.x * (k.y + dims.y * k.z));
}

// Offset of voxel i within its 8^3 brick, x fastest (medium/grid.rs `voxel_offset`).
fn brick_offset(i: vec3<i32>) -> u32 {
    let l = i & vec3<i32>(7);
    return u32(l.x | (l.y << 3u) | (l.z << 6u));
}
