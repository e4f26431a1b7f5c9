//! The collect step (Sec. 4.1, Alg. 2): every cell of a slab reads the temporary buffers T of
//! all the face's directions and adds the light they scatter into each storage bin to U of
//! the next order (Eq. 4: U_d += sigma_s sum_i F[d][i] T_i) and, from the second order on, the
//! light scattered towards the camera to J (in-scattered radiance per unit sigma_s). One
//! thread per cell: no atomics.
//!
//! Departure from the paper: J towards the viewer is read from the fine propagation bins
//! (J += sum_i F[view bin][i] T_i), not from the m storage bins' I: the fine table keeps an
//! anisotropic lobe that m = 6 flattens, and costs one table row per cell. The rows are the
//! table's `view` ones: the true phase's under the delta-M split (delta_m.rs), whose U uses the
//! residual lobe.

use glam::Vec3;
use rayon::prelude::*;

use super::directions::Directions;
use super::grid::LpmGrid;
use super::phase_table::PhaseTable;
use super::propagate::FaceFrame;
use crate::stages::Progress;

/// What collect adds to, and where the viewer is.
pub struct Targets<'a> {
    pub u_cur: &'a mut [Vec3],
    /// `None` for the first propagation (its single scattering is the compositor's, exact).
    pub j: Option<&'a mut [Vec3]>,
    pub camera: Vec3,
    pub albedo: Vec3,
}

/// Adds the slab `w0..w1` of face `ff`: `t` holds the face's directions' buffers one after
/// the other, each `(w1 - w0) x map` long. Planes not yet started when the host cancels are
/// skipped (the caller reports the cancel and discards U).
#[allow(clippy::too_many_arguments)]
pub fn collect(grid: &LpmGrid, dirs: &Directions, table: &PhaseTable, ff: &FaceFrame, t: &[Vec3], w0: usize, w1: usize, targets: Targets, progress: &dyn Progress) {
    let m = table.m;
    let n = table.n;
    let [nx, ny, _] = grid.dims;
    let plane = nx * ny;
    let slab_len = (w1 - w0) * ff.map_len();
    let first = ff.face * dirs.per_face();
    let face_dirs = first..first + dirs.per_face();
    // Grid-coordinate range of the slab along the face's axis.
    let (a0, a1) = if ff.forward { (w0, w1) } else { (ff.nw - w1, ff.nw - w0) };
    let range = |axis: usize, n_axis: usize| if axis == ff.axes.2 { a0..a1 } else { 0..n_axis };
    let (xr, yr, zr) = (range(0, nx), range(1, ny), range(2, grid.dims[2]));
    // The storage table by incoming direction: m contiguous weights per direction.
    let by_incoming: Vec<f32> = face_dirs.clone().flat_map(|i| (0..m).map(move |d| table.storage[d * n + i])).collect();
    let Targets { u_cur, j, camera, albedo } = targets;
    // The targets hold the grid's planes from z0 on (a slab's box out of core, grid.rs).
    let z0 = grid.offset[2];
    let work = |z: usize, u_plane: &mut [Vec3], mut j_plane: Option<&mut [Vec3]>| {
        if progress.cancelled() {
            return;
        }
        let mut acc = vec![Vec3::ZERO; m];
        let mut cell = |x: usize, y: usize| {
            let c = [x, y, z];
            let idx = grid.index(c);
            let sigma_s = albedo * grid.sigma_t[idx];
            let (u, v, wg) = (c[ff.axes.0], c[ff.axes.1], c[ff.axes.2]);
            let w = if ff.forward { wg } else { ff.nw - 1 - wg } - w0;
            let pos = w * ff.map_len() + v * ff.nu + u;
            acc.iter_mut().for_each(|a| *a = Vec3::ZERO);
            let view_row = j_plane.as_ref().map(|_| table.view_row(dirs.bin_of((camera - grid.centre(c)).normalize_or(Vec3::Z))));
            let mut jsum = Vec3::ZERO;
            // An empty cell scatters nothing into U; its J still feeds the upsampling.
            let scatters = sigma_s != Vec3::ZERO;
            for (li, gi) in face_dirs.clone().enumerate() {
                let tv = t[li * slab_len + pos];
                if scatters {
                    let wts = &by_incoming[li * m..(li + 1) * m];
                    for (a, &f) in acc.iter_mut().zip(wts) {
                        *a += tv * f;
                    }
                }
                if let Some(row) = view_row {
                    jsum += tv * row[gi];
                }
            }
            let local = idx - (z - z0) * plane;
            if scatters {
                for (d, a) in acc.iter().enumerate() {
                    u_plane[local * m + d] += sigma_s * *a;
                }
            }
            if let Some(jp) = j_plane.as_deref_mut() {
                jp[local] += jsum;
            }
        };
        // Cells in the order of the face's map where a plane allows it (y first when u is y:
        // the faces along x), so that T's p rows are read a cache line at a time, not one
        // line a cell; each cell's sums are the same whatever the order.
        if ff.axes.0 == 1 {
            for x in xr.clone() {
                for y in yr.clone() {
                    cell(x, y);
                }
            }
        } else {
            for y in yr.clone() {
                for x in xr.clone() {
                    cell(x, y);
                }
            }
        }
    };
    match j {
        Some(j) => u_cur
            .par_chunks_mut(plane * m)
            .zip(j.par_chunks_mut(plane))
            .enumerate()
            .map(|(k, x)| (k + z0, x))
            .filter(|(z, _)| zr.contains(z))
            .for_each(|(z, (up, jp))| work(z, up, Some(jp))),
        None => u_cur.par_chunks_mut(plane * m).enumerate().map(|(k, x)| (k + z0, x)).filter(|(z, _)| zr.contains(z)).for_each(|(z, up)| work(z, up, None)),
    }
}
