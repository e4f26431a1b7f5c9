// Prelude of the kernels that run one invocation per column (u, v) of a grid whose cells are
// x fastest, depth slowest (pop/init.wgsl, pop/sum.wgsl): the column's index, or NO_COLUMN for
// the invocations beyond the grid.

const NO_COLUMN: u32 = 0xffffffffu;

fn column_index(gid: vec3<u32>, dims: vec3<u32>) -> u32 {
    if (gid.x >= dims.x || gid.y >= dims.y) {
        return NO_COLUMN;
    }
    return gid.x + dims.x * gid.y;
}
