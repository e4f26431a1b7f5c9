// Per (direction of the chunk, list slot): the sort key (pixel, depth bits, particle index) of
// core network/visibility.rs `sort_key`, padding keys (all NONE, sorted last) in the slots past
// N; with `Opacity::Boundary` also the particle's optical depth to the medium's boundary
// against the direction (`optical_depth`, the CPU's steps and order).

@group(0) @binding(4) var<storage, read_write> keys: array<vec4<u32>>;
// Per (direction of the chunk, particle): optical depth to the boundary (RGB).
@group(0) @binding(5) var<storage, read_write> to_boundary: array<vec4<f32>>;

// visibility.rs `window_cell`: floor, then clamped to the window.
fn cell(a: f32) -> u32 {
    let radius = params.centre_radius.w;
    let m = params.counts.y;
    let c = floor((a + radius) / (2.0 * radius) * f32(m));
    return u32(clamp(c, 0.0, f32(m - 1u)));
}

// visibility.rs `total_order_bits`: unsigned order = f32::total_cmp.
fn total_order_bits(a: f32) -> u32 {
    let b = bitcast<u32>(a);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = invocation(gid);
    let n = params.counts.x;
    let len = params.counts.z;
    if (i >= len * params.counts.w) {
        return;
    }
    let d = i / len;
    let k = i % len;
    if (k >= n) {
        keys[i] = vec4<u32>(NONE);
        return;
    }
    let x = positions[k].xyz;
    let u = basis[3u * d].xyz;
    let v = basis[3u * d + 1u].xyz;
    let w = basis[3u * d + 2u].xyz;
    let r = x - params.centre_radius.xyz;
    keys[i] = vec4<u32>(cell(dot3(r, u)) + params.counts.y * cell(dot3(r, v)), total_order_bits(dot3(x, w)), k, 0u);
    if (params.modes.y == 0u) {
        to_boundary[d * n + k] = vec4<f32>(optical_depth(x, -w, NO_LIMIT, params.misc.x, BOUNDARY_STEPS), 0.0);
    }
}
