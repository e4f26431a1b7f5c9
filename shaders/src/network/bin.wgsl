// The splat's binning: invocation p < N writes particle p's (tile, particle) keys, one per
// tile its kernel box overlaps, from its first slot `offsets[p]` (the host's prefix sum of
// the boxes' tile counts); invocation i < (list length - pairs) pads the list's tail.

@group(0) @binding(1) var<storage, read> particles: array<Particle>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys: array<vec4<u32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * params.pairs.w + gid.x;
    let padding = params.pairs.y - params.pairs.x;
    if (i < padding) {
        keys[params.pairs.x + i] = vec4<u32>(PAD);
    }
    if (i >= params.dims.w) {
        return;
    }
    let p = particles[i];
    // An empty box (a particle outside the grid): no pairs, as the host counted.
    if (any(p.lo.xyz > p.hi.xyz)) {
        return;
    }
    let lo = vec3<u32>(p.lo.xyz) / params.tiles.x;
    let hi = vec3<u32>(p.hi.xyz) / params.tiles.x;
    var slot = offsets[i];
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            for (var x = lo.x; x <= hi.x; x++) {
                keys[slot] = vec4<u32>(x + params.tiles.y * (y + params.tiles.z * z), i, 0u, 0u);
                slot++;
            }
        }
    }
}
