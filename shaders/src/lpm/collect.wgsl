// lpm's collect step (volscatter-core lpm/collect.rs, Alg. 2, Eq. 4): one invocation per cell
// of one face's slab (dispatch [map tiles, layers, 1]) reads T of the face's p directions and
// writes this face's share of U of the next order, sigma_s sum_i F[d][i] T_i for every
// storage bin d, and of J, sum_i F[view bin][i] T_i. The host adds both to its U and J, face
// after face as the CPU does; the sums over i run in the CPU's order. No atomics.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> sigma: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> t_in: array<vec4<f32>>;
// The storage table by incoming direction: weight of direction i into bin d at i * m + d.
@group(0) @binding(3) var<storage, read> by_incoming: array<f32>;
// The view table (the true phase function's, lpm/phase_table.rs `view_rows`), n x 16 rows of
// n: row = the outgoing sub-sample of a bin.
@group(0) @binding(4) var<storage, read> fine: array<f32>;
// Each cell's row towards the camera (lpm/directions.rs `view_index`, on the host).
@group(0) @binding(5) var<storage, read> view_bin: array<u32>;
@group(0) @binding(6) var<storage, read_write> u_out: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> j_out: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let map_len = params.map.z;
    if (gid.x >= map_len) {
        return;
    }
    let k = gid.y * map_len + gid.x;
    let slab_len = params.map.w;
    let p = params.sweep.z;
    let m = params.sweep.w;
    let first = params.dirs.y;
    let sigma_s = params.albedo.xyz * sigma[k].xyz;
    for (var d = 0u; d < m; d++) {
        var acc = vec3<f32>(0.0);
        for (var li = 0u; li < p; li++) {
            acc += t_in[li * slab_len + k].xyz * by_incoming[(first + li) * m + d];
        }
        u_out[k * m + d] = vec4<f32>(sigma_s * acc, 0.0);
    }
    if (params.dirs.z != 0u) {
        let row = view_bin[k] * params.dirs.x + first;
        var j = vec3<f32>(0.0);
        for (var li = 0u; li < p; li++) {
            j += t_in[li * slab_len + k].xyz * fine[row + li];
        }
        j_out[k] = vec4<f32>(j, 0.0);
    }
}
