//! The collect step (Sec. 4.1, Alg. 2): every cell of a layer reads the temporary buffers T of
//! all the face's directions and adds the light they scatter into each storage bin to U of
//! the next order (Eq. 4: U_d += sigma_s sum_i F[d][i] T_i) and, from the second order on, the
//! light scattered towards the camera to J (in-scattered radiance per unit sigma_s). Each cell
//! is written by one thread: no atomics.
//!
//! Departure from the paper: J towards the viewer is read from the fine propagation bins
//! (J += sum_i F[view][i] T_i), not from the m storage bins' I: the fine table keeps an
//! anisotropic lobe that m = 6 flattens, and costs one table row per cell. The rows are the
//! table's `view` ones (phase_table.rs): the true phase function's, towards the sub-sample of
//! the camera's bin that the camera's direction falls in, so that a lobe narrower than a bin
//! is not blurred across it; under the delta-M split (delta_m.rs) U uses the residual lobe.

use glam::{Vec3, Vec3A};
use super::stream::for_each_chunk;

use super::directions::Directions;
use super::grid::LpmGrid;
use super::phase_table::PhaseTable;
use super::propagate::FaceFrame;

/// What collect adds to, and where the viewer is.
pub struct Targets<'a> {
    pub u_cur: &'a mut [Vec3],
    /// `None` for the first propagation (its single scattering is the compositor's, exact).
    pub j: Option<&'a mut [Vec3]>,
    pub camera: Vec3,
    pub albedo: Vec3,
}

/// The storage table by incoming direction for face `face`'s directions: m contiguous weights
/// per direction (collect's inner loop reads a direction's row at a time).
pub fn by_incoming(dirs: &Directions, table: &PhaseTable, face: usize) -> Vec<f32> {
    let first = face * dirs.per_face();
    (first..first + dirs.per_face()).flat_map(|i| (0..table.m).map(move |d| table.storage[d * table.n + i])).collect()
}

/// Adds layers `ws` of face `ff`, right after they were propagated: `t` holds the face's
/// directions' rays' mean radiance over the layers' cells, direction after direction, each
/// `stride` long, layer after layer within (`t[li * stride + (w - ws.start) * map + k]`, k = v nu
/// + u). `weights` is `by_incoming` for the face. Collected a few layers at a time (stream.rs
/// `sweep_slab`), T is read while it is still in cache: the whole slab's T of every direction,
/// read cell by cell, made each cell wait on memory once a direction. Rows (or the grid's
/// z-planes, for a face across z) run in parallel where `parallel`.
#[allow(clippy::too_many_arguments)]
pub fn collect_layers(grid: &LpmGrid, dirs: &Directions, table: &PhaseTable, weights: &[f32], ff: &FaceFrame, t: &[Vec3], stride: usize, ws: std::ops::Range<usize>, targets: Targets, parallel: bool) {
    let m = table.m;
    let [nx, ny, _] = grid.dims;
    let plane = nx * ny;
    let first = ff.face * dirs.per_face();
    let p = dirs.per_face();
    let Targets { u_cur, j, camera, albedo } = targets;
    let (z0, o) = (grid.offset[2], grid.offset);
    // A layer's grid coordinate along the face's axis.
    let grid_w = |w: usize| if ff.forward { w } else { ff.nw - 1 - w };
    // One cell: its U (m values) and J, both within the caller's chunk at `local`.
    // `acc`: the row's m accumulators, SIMD: the sums over the face's directions are most of a
    // sweep's time.
    let cell = |c: [usize; 3], acc: &mut [Vec3A], u_chunk: &mut [Vec3], j_chunk: Option<&mut [Vec3]>, local: usize| {
        let idx = grid.index(c);
        let sigma_s = albedo * grid.sigma_t[idx];
        let k = (grid_w(c[ff.axes.2]) - ws.start) * ff.map_len() + c[ff.axes.1] * ff.nu + c[ff.axes.0];
        acc.iter_mut().for_each(|a| *a = Vec3A::ZERO);
        let view_row = j_chunk.as_ref().map(|_| table.view_row(dirs.view_index((camera - grid.centre(c)).normalize_or(Vec3::Z))));
        let mut jsum = Vec3A::ZERO;
        // An empty cell scatters nothing into U; its J still feeds the upsampling.
        let scatters = sigma_s != Vec3::ZERO;
        for li in 0..p {
            let tv = Vec3A::from(t[li * stride + k]);
            if scatters {
                for (a, &f) in acc.iter_mut().zip(&weights[li * m..(li + 1) * m]) {
                    *a += tv * f;
                }
            }
            if let Some(row) = view_row {
                jsum += tv * row[first + li];
            }
        }
        if scatters {
            for (d, a) in acc.iter().enumerate() {
                u_chunk[local * m + d] += sigma_s * Vec3::from(*a);
            }
        }
        if let Some(jc) = j_chunk {
            jc[local] += Vec3::from(jsum);
        }
    };
    let [dx, dy, _] = grid.dims;
    if ff.axes.2 == 2 {
        // z-layers are planes of the grid: their rows.
        let (za, zb) = (grid_w(ws.start).min(grid_w(ws.end - 1)), grid_w(ws.start).max(grid_w(ws.end - 1)) + 1);
        let (pa, pb) = (za - z0, zb - z0);
        let u_planes = &mut u_cur[pa * plane * m..pb * plane * m];
        let j_planes = j.map(|j| &mut j[pa * plane..pb * plane]);
        for_each_chunk(parallel, u_planes, nx * m, j_planes, nx, |r, ur, mut jr| {
            let (z, y) = (za + r / ny, r % ny);
            let mut acc = vec![Vec3A::ZERO; m];
            for x in 0..dx {
                cell([x + o[0], y + o[1], z], &mut acc, ur, jr.as_deref_mut(), x);
            }
        });
    } else {
        // x- or y-layers cross every plane, a row each: the planes.
        for_each_chunk(parallel, u_cur, plane * m, j, plane, |k, up, mut jp| {
            let z = k + z0;
            let mut acc = vec![Vec3A::ZERO; m];
            for w in ws.clone() {
                let wg = grid_w(w);
                if ff.axes.2 == 0 {
                    for y in 0..dy {
                        cell([wg, y + o[1], z], &mut acc, up, jp.as_deref_mut(), (wg - o[0]) + nx * y);
                    }
                } else {
                    for x in 0..dx {
                        cell([x + o[0], wg, z], &mut acc, up, jp.as_deref_mut(), x + nx * (wg - o[1]));
                    }
                }
            }
        });
    }
}
