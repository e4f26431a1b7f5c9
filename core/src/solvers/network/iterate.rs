//! The iteration of Eq. 2 over the illumination network, with alpha x albedo where the
//! printed text has alpha x alpha:
//!
//!   I[p, i] = (1 - alpha) I[vp, i] + alpha (E[vp, i] + a sum_d P[i, d] I[vp, d])
//!
//! I[p, i] is the scattered radiance arriving at particle p travelling along direction i, vp
//! its upstream neighbour in direction i, alpha the pair's opacity, E the direct light's first
//! scattering (direct.rs) and P the row-normalised phase matrix. A column's first particle
//! receives the light scattered in the gap from the medium's boundary, with its own source
//! standing for the gap's (departure: the paper's first particle receives only the sky, which
//! loses that gap's scattering; the sky and the lights themselves are in E, exactly).
//!
//! Departure from the paper's Jacobi update, same fixed point: each iteration first forms the
//! scattered source Q = E + a P I (the matrix product), then sweeps every direction's lists
//! upstream first, so that one iteration carries each scattering order along whole columns
//! instead of one particle per iteration. The residual is then the next order's share, which
//! falls geometrically (by about the albedo times the mean chance of scattering again).

use glam::Vec3;
use rayon::prelude::*;

use super::visibility::{DirectionLinks, NONE};

pub struct Iterated {
    /// N x D, row-major.
    pub radiance: Vec<Vec3>,
    /// Residual after each iteration: sum |I_new - I_old| / sum |I_new| (channel sums).
    pub residuals: Vec<f64>,
}

/// Stops before the next iteration once `progress` is cancelled (an iteration is well under
/// 100 ms at the largest settings on one core); the caller then discards the result.
#[allow(clippy::too_many_arguments)]
pub fn iterate(links: &[DirectionLinks], phase: &[f32], first: &[Vec3], albedo: Vec3, max_iterations: u32, threshold: f32, start: Option<Vec<Vec3>>, progress: &dyn crate::stages::Progress) -> Iterated {
    let d = links.len();
    let n = first.len() / d.max(1);
    let mut radiance = start.filter(|s| s.len() == n * d).unwrap_or_else(|| vec![Vec3::ZERO; n * d]);
    let mut source = vec![Vec3::ZERO; n * d];
    let mut residuals = Vec::new();
    for _ in 0..max_iterations {
        if progress.cancelled() {
            break;
        }
        source.par_chunks_mut(d).zip(radiance.par_chunks(d)).zip(first.par_chunks(d)).for_each(|((q, i_in), e)| {
            for (i, qi) in q.iter_mut().enumerate() {
                let row = &phase[i * d..(i + 1) * d];
                let s: Vec3 = row.iter().zip(i_in).map(|(&w, &l)| l * w).sum();
                *qi = e[i] + albedo * s;
            }
        });
        // Swept per direction into direction-major columns, then written back row-major.
        let columns: Vec<Vec<Vec3>> = links
            .par_iter()
            .enumerate()
            .map(|(i, l)| {
                let mut col = vec![Vec3::ZERO; n];
                for &p in &l.order {
                    let p = p as usize;
                    let a = l.alpha[p];
                    col[p] = match l.up[p] {
                        NONE => a * source[p * d + i],
                        up => (Vec3::ONE - a) * col[up as usize] + a * source[up as usize * d + i],
                    };
                }
                col
            })
            .collect();
        let (mut change, mut total) = (0.0f64, 0.0f64);
        for (i, col) in columns.iter().enumerate() {
            for (p, &v) in col.iter().enumerate() {
                let old = &mut radiance[p * d + i];
                change += (v - *old).abs().element_sum() as f64;
                total += v.abs().element_sum() as f64;
                *old = v;
            }
        }
        let r = if total > 0.0 { change / total } else { 0.0 };
        residuals.push(r);
        if r <= threshold as f64 {
            break;
        }
    }
    Iterated { radiance, residuals }
}
