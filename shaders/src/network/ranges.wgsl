// Each tile's run [start, end) in the sorted (tile, particle) list: the entries where the tile
// changes. Tiles no particle reaches keep the zeroed empty range.

@group(0) @binding(1) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> ranges: array<vec2<u32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * params.pairs.w + gid.x;
    if (i >= params.pairs.x) {
        return;
    }
    let t = keys[i].x;
    if (i == 0u || keys[i - 1u].x != t) {
        ranges[t].x = i;
    }
    if (i + 1u == params.pairs.x || keys[i + 1u].x != t) {
        ranges[t].y = i + 1u;
    }
}
