//! Light propagation in one light's grid (Sec. 4.2-4.3, Eq. 1-8), ping-pong between two
//! grids, gathering from the six neighbours.
//!
//! Every cell holds the energy P of light still travelling (W/m^2 per cell, per RGB channel)
//! and its anisotropy a about the principal direction d: L(x, w) = P f_hg(w . d, a). Per
//! iteration each source cell sends P F(a) to its neighbours, with F the HG cumulative
//! distribution over the solid angle each neighbour subtends (Eq. 1-3): the cone of half-angle
//! 45 degrees to the cell in front, the band from 45 to 135 degrees split in four quarters to
//! the side cells, the remaining cone to the cell behind. The fractions sum to one, so the
//! scheme moves energy and never creates it. On the way, absorption only (Eq. 2) and the
//! anisotropy decay a g^(sigma_s t) (Eq. 4), both with the coefficients averaged over the two
//! cells; contributions combine by Eq. 5-6.
//!
//! Departure: the length of light path one iteration stands for. The paper takes t = one cell
//! edge h. That is right for light moving along d (a near 1), but once the light is isotropic
//! the lattice is a random walk with steps h, whose mean square displacement per step is h^2;
//! physical diffusion gives 2 l* per unit path (l* = 1 / sigma_tr, sigma_tr = sigma_s (1 - g) +
//! sigma_a). Taking t = h as path length makes the fluence of diffuse light depend on the grid
//! (docs/solvers/pop.md has the numbers). With `diffusion_correction` an
//! iteration stands for the path s = h kappa with kappa = |a| k_d + (1 - |a|) h sigma_tr / 2,
//! blending by the lobe's mean cosine: for directional light k_d = (front - back) / a, the path
//! that makes the lattice's drift per step equal the lobe's mean cosine times the path (about
//! one cell); for isotropic light the diffusion-matched h sigma_tr / 2.
//! The fluence a packet leaves in a cell is P s / h (fluence = energy x path length per
//! volume), and absorption and the decay of a use the same s. Energy accounting is
//! unchanged: the fractions still sum to one.
//!
//! Option `moment_anisotropy` (RunOptions): Eq. 5-6 give every part of a lobe the source's a
//! about d, so light sent sideways or back is a lobe along d again on arrival; on the dense
//! cloud that carries light 15-20 optical depths in and leaves the lit face 3x too dark
//! (docs/pop-dense-clouds.md). With the option each part leaves with the mean cosine of its
//! own cone (`lobe_moments`; the net flux along d is kept), and light in empty cells is
//! re-emitted isotropically. Off by default: it darkens the g 0.7 cube (see the doc).

use glam::Vec3;
use rayon::prelude::*;

use super::init::Initial;
use super::light_grid::LightGrid;
use crate::error::{Error, Result};
use crate::phase::{hg, hg_cone_fraction};
use crate::stages::Progress;

const COS_45: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// How one source cell emits this iteration (also the radial grids', radial/propagate.rs).
#[derive(Clone, Copy, Default)]
pub(crate) struct Emit {
    /// Fractions of P towards the cell in front (along d), each side cell, and behind.
    pub front: Vec3,
    pub side: Vec3,
    pub back: Vec3,
    /// Light path this iteration stands for (metres).
    pub path: Vec3,
    /// Anisotropy each part leaves with, before the decay of Eq. 4: the source's own a, or,
    /// with `RunOptions::moment_anisotropy`, the mean cosine of its cone (`lobe_moments`).
    pub a_front: Vec3,
    pub a_side: Vec3,
    pub a_back: Vec3,
}

#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PropagationStats {
    pub iterations: u32,
    /// Energy scattered into the grid, left through its faces, absorbed, and still travelling
    /// when the iterations stopped (dropped), per cell cross-section as in `Initial`.
    pub injected: [f32; 3],
    pub escaped: [f32; 3],
    pub absorbed: [f32; 3],
    pub residual: [f32; 3],
    /// Energy-weighted mean anisotropy of the light still travelling at the end (what the
    /// isotropic residuum, residuum.rs, treats as isotropic: Sec. 5.4's |a| < epsilon_a).
    pub residual_anisotropy: [f32; 3],
    /// Per cell, the packets still travelling at the end: filled only with
    /// `RunOptions::keep_remaining` (the isotropic residuum gathers them).
    #[serde(skip)]
    pub remaining: Vec<Vec3>,
}

#[inline]
pub(crate) fn per_channel(a: Vec3, f: impl Fn(f32) -> f32) -> Vec3 {
    Vec3::new(f(a.x), f(a.y), f(a.z))
}

/// HG anisotropy parameter clamped away from the delta (|a| = 1).
#[inline]
pub(crate) fn clamp_a(a: f32) -> f32 {
    a.clamp(-0.9995, 0.9995)
}

#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Let the isotropic part of light that has left the medium escape (see run_with).
    pub vacuum_escape: bool,
    /// Return the packets still travelling when the iterations stop in
    /// `PropagationStats::remaining` (for the isotropic residuum, Sec. 5.4).
    pub keep_remaining: bool,
    /// Each part of a lobe leaves with the mean cosine of its own cone, not the source's a,
    /// and light in empty cells is re-emitted isotropically (`PopSettings::moment_anisotropy`,
    /// `lobe_moments`).
    pub moment_anisotropy: bool,
}

/// The fractions of a lobe of anisotropy `a` (per channel) sent to the cell in front, to each
/// of the four side cells and to the cell behind (Eq. 1-3: HG energy in the 45-degree cones and
/// the quarters of the band between them). They sum to one.
pub(crate) fn lobe_fractions(a: Vec3) -> (Vec3, Vec3, Vec3) {
    let front = per_channel(a, |a| hg_cone_fraction(COS_45, clamp_a(a)));
    let back = Vec3::ONE - per_channel(a, |a| hg_cone_fraction(-COS_45, clamp_a(a)));
    let side = ((Vec3::ONE - front - back) * 0.25).max(Vec3::ZERO);
    (front, side, back)
}

/// First moment about d of an HG lobe of anisotropy `g` over cos in [lo, hi]: the integral
/// of cos p(cos) (p normalised over the sphere). Closed form with u = 1 + g^2 - 2 g cos:
/// (1 - g^2) / (4 g^2) [(1 + g^2) u^-1/2 + u^1/2]; over [-1, 1] it is g. In f64: the two
/// terms cancel to O(g) for small g.
pub(crate) fn hg_cone_moment(lo: f32, hi: f32, g: f32) -> f32 {
    let g = clamp_a(g) as f64;
    if g.abs() < 1e-4 {
        return ((hi as f64).powi(2) - (lo as f64).powi(2)) as f32 * 0.25;
    }
    let f = |c: f32| {
        let u = (1.0 + g * g - 2.0 * g * c as f64).max(1e-24);
        (1.0 + g * g) / u.sqrt() + u.sqrt()
    };
    ((1.0 - g * g) / (4.0 * g * g) * (f(hi) - f(lo))) as f32
}

/// The mean cosine about d of the light sent front, to each side and back by a lobe of
/// anisotropy `a` (fractions `front`, `side`, `back` from `lobe_fractions`): its first moment
/// over each cone divided by the cone's energy. Weighted by the fractions they sum to `a`, so
/// the net flux along d is what the lobe carries, however it is split.
pub(crate) fn lobe_moments(a: Vec3, front: Vec3, side: Vec3, back: Vec3) -> (Vec3, Vec3, Vec3) {
    let mean = |m: Vec3, f: Vec3| Vec3::select(f.cmpgt(Vec3::splat(1e-9)), m / f.max(Vec3::splat(1e-9)), Vec3::ZERO);
    let mf = per_channel(a, |a| hg_cone_moment(COS_45, 1.0, a));
    let mb = per_channel(a, |a| hg_cone_moment(-1.0, -COS_45, a));
    let ms = per_channel(a, |a| hg_cone_moment(-COS_45, COS_45, a)) * 0.25;
    // Clamped into each cone's range of cosines: for a nearly delta lobe the back cone's
    // moment and energy are both ~1e-7 and their f32 ratio can fall outside it.
    let (c, one) = (Vec3::splat(COS_45), Vec3::ONE);
    (mean(mf, front).clamp(c, one), mean(ms, side).clamp(-c, c), mean(mb, back).clamp(-one, -c))
}

/// kappa: the light path one iteration stands for, in cell lengths `h` (see the module doc),
/// from the fractions actually sent front and back; 1 without the diffusion correction.
#[allow(clippy::too_many_arguments)]
pub(crate) fn path_factor(diffusion_correction: bool, front: Vec3, back: Vec3, a: Vec3, sigma_s: Vec3, sigma_a: Vec3, g: f32, h: f32) -> Vec3 {
    if !diffusion_correction {
        return Vec3::ONE;
    }
    let sigma_tr = sigma_s * (1.0 - g.abs()) + sigma_a;
    let iso = (sigma_tr * (0.5 * h)).min(Vec3::splat(64.0));
    let aa = a.abs().min(Vec3::ONE);
    // Directional part: the path per step that matches the lattice's drift (front - back) h to
    // the lobe's a s, between 0.75 (a -> 0) and 1 (a -> 1).
    let drift = front - back;
    // Signed: a backward lobe (a < 0) drifts backwards, and its path is positive too.
    let ball = Vec3::select(aa.cmpgt(Vec3::splat(1e-3)), drift / Vec3::select(a.cmpge(Vec3::ZERO), a.max(Vec3::splat(1e-3)), a.min(Vec3::splat(-1e-3))), Vec3::splat(0.75));
    aa * ball + (Vec3::ONE - aa) * iso
}

pub struct Propagation<'a> {
    pub grid: &'a LightGrid,
    /// Medium phase anisotropy.
    pub g: f32,
    /// Per cell: cosine between d and the direction from the cell to the camera.
    pub mu: &'a [f32],
    pub diffusion_correction: bool,
    pub max_iterations: u32,
    pub residual_threshold: f32,
}

impl Propagation<'_> {
    fn emit(&self, c: usize, a: Vec3, moments: bool) -> Emit {
        let grid = self.grid;
        let (front, side, back) = lobe_fractions(a);
        let kappa = path_factor(self.diffusion_correction, front, back, a, grid.sigma_s[c], grid.sigma_a[c], self.g, grid.h);
        let (a_front, a_side, a_back) = if moments { lobe_moments(a, front, side, back) } else { (a, a, a) };
        Emit { front, side, back, path: kappa * grid.h, a_front, a_side, a_back }
    }

    /// Runs Eq. 1-8 from the injected packets; adds the view-dependent in-scattered radiance
    /// per unit sigma_s, J = sum P (s / h) f_hg(mu, a g), into `j_acc` (the accumulation grid,
    /// Eq. 7-8, with the phase function applied: see accumulate.rs) and returns energy
    /// statistics.
    pub fn run(&self, init: &Initial, a_scattered: f32, j_acc: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
        self.run_with(RunOptions::default(), init, a_scattered, j_acc, progress)
    }

    /// `run` with options (the GPU port, shaders/src/pop, has `keep_remaining` but not
    /// `vacuum_escape`).
    pub fn run_with(&self, opts: RunOptions, init: &Initial, a_scattered: f32, j_acc: &mut [Vec3], progress: &dyn Progress) -> Result<PropagationStats> {
        let grid = self.grid;
        let n = grid.len();
        let (nx, ny, nz) = (grid.dims.x as usize, grid.dims.y as usize, grid.dims.z as usize);
        let slab = nx * ny;
        let h = grid.h;
        let g = self.g;
        let ln_g = g.abs().max(1e-6).ln();
        let mut p = init.packets.clone();
        let mut a = vec![Vec3::splat(a_scattered); n];
        let mut p_next = vec![Vec3::ZERO; n];
        let mut a_next = vec![Vec3::ZERO; n];
        let mut emit = vec![Emit::default(); n];
        let injected: Vec3 = p.iter().copied().sum();

        // Iteration 0: the packets were born in their cells, on average half a cell from the
        // exit: half the fluence of a full step there.
        let escaped_at = |c: usize, e: &Emit, pc: Vec3| -> Vec3 {
            let (i, j, k) = (c % nx, (c / nx) % ny, c / slab);
            let sides = (i == 0) as u32 + (i == nx - 1) as u32 + (j == 0) as u32 + (j == ny - 1) as u32;
            pc * (e.side * sides as f32 + if k == nz - 1 { e.front } else { Vec3::ZERO } + if k == 0 { e.back } else { Vec3::ZERO })
        };
        let mut esc_next = emit
            .par_iter_mut()
            .zip(j_acc.par_iter_mut())
            .enumerate()
            .map(|(c, (e, jc))| {
                if progress.cancelled() {
                    return Vec3::ZERO;
                }
                *e = self.emit(c, a[c], opts.moment_anisotropy);
                let w = p[c] * e.path / h * 0.5;
                *jc += w * per_channel(a[c], |ac| hg(self.mu[c], clamp_a(ac * g)));
                escaped_at(c, e, p[c])
            })
            .sum::<Vec3>();
        // An iteration over a fine grid takes a core tenths of a second: the cancel is read
        // before each and per slab within its gather.
        if progress.cancelled() {
            return Err(Error::Cancelled);
        }
        let mut escaped = Vec3::ZERO;
        let mut absorbed = Vec3::ZERO;
        let mut remaining = injected;
        let mut before = injected;
        let mut iterations = 0;
        let target = injected * self.residual_threshold;
        while iterations < self.max_iterations && remaining.cmpgt(target).any() && remaining.max_element() > 0.0 {
            iterations += 1;
            // Gather (Eq. 2-6).
            let (p_ref, e_ref) = (&p, &emit);
            p_next.par_chunks_mut(slab).zip(a_next.par_chunks_mut(slab)).enumerate().for_each(|(k, (pn, an))| {
                if progress.cancelled() {
                    return;
                }
                for jj in 0..ny {
                    for ii in 0..nx {
                        let dst = ii + nx * jj + slab * k;
                        let (sa_d, ss_d) = (grid.sigma_a[dst], grid.sigma_s[dst]);
                        let mut l = Vec3::ZERO;
                        let mut la = Vec3::ZERO;
                        let mut add = |src: usize, frac: Vec3, a_src: Vec3| {
                            let ps = p_ref[src];
                            if ps == Vec3::ZERO {
                                return;
                            }
                            let e = &e_ref[src];
                            let sa = 0.5 * (grid.sigma_a[src] + sa_d);
                            let ss = 0.5 * (grid.sigma_s[src] + ss_d);
                            // exp(0) = 1 exactly: skipping it in empty or non-absorbing
                            // cells changes nothing but the time.
                            let t = if sa == Vec3::ZERO { Vec3::ONE } else { (-sa * e.path).exp() };
                            let dl = ps * frac * t;
                            let da = if ss == Vec3::ZERO { a_src } else { a_src * (ss * e.path * ln_g).exp() };
                            l += dl;
                            la += dl * da;
                        };
                        if k > 0 {
                            add(dst - slab, e_ref[dst - slab].front, e_ref[dst - slab].a_front);
                        }
                        if k + 1 < nz {
                            add(dst + slab, e_ref[dst + slab].back, e_ref[dst + slab].a_back);
                        }
                        if ii > 0 {
                            add(dst - 1, e_ref[dst - 1].side, e_ref[dst - 1].a_side);
                        }
                        if ii + 1 < nx {
                            add(dst + 1, e_ref[dst + 1].side, e_ref[dst + 1].a_side);
                        }
                        if jj > 0 {
                            add(dst - nx, e_ref[dst - nx].side, e_ref[dst - nx].a_side);
                        }
                        if jj + 1 < ny {
                            add(dst + nx, e_ref[dst + nx].side, e_ref[dst + nx].a_side);
                        }
                        let o = ii + nx * jj;
                        pn[o] = l;
                        // Eq. 6: energy-weighted mean of the decayed anisotropies.
                        an[o] = Vec3::select(l.cmpgt(Vec3::splat(1e-30)), la / l.max(Vec3::splat(1e-30)), Vec3::ZERO);
                    }
                }
            });
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            std::mem::swap(&mut p, &mut p_next);
            std::mem::swap(&mut a, &mut a_next);
            // Accumulate (Eq. 7-8) and prepare the next emission.
            let a_ref = &a;
            let (arrived, esc, vac) = emit
                .par_iter_mut()
                .zip(j_acc.par_iter_mut())
                .zip(p.par_iter_mut())
                .enumerate()
                .map(|(c, ((e, jc), pc))| {
                    let arrived = *pc;
                    if arrived == Vec3::ZERO || progress.cancelled() {
                        *e = Emit::default();
                        return (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
                    }
                    let mut vac = Vec3::ZERO;
                    if opts.vacuum_escape && grid.sigma_s[c] == Vec3::ZERO && grid.sigma_a[c] == Vec3::ZERO {
                        // Outside the medium light does not scatter: its isotropic part streams
                        // away instead of random-walking back in, as the lattice would let it.
                        // The directional part (|a|) keeps travelling along d and may meet the
                        // medium again downstream.
                        let keep = a_ref[c].abs().min(Vec3::ONE);
                        vac = *pc * (Vec3::ONE - keep);
                        *pc *= keep;
                    }
                    // With `moment_anisotropy`, light in an empty cell is re-emitted
                    // isotropically (unless it escapes, above): see the option's doc.
                    let empty = grid.sigma_s[c] == Vec3::ZERO && grid.sigma_a[c] == Vec3::ZERO;
                    let a_emit = if opts.moment_anisotropy && !opts.vacuum_escape && empty { Vec3::ZERO } else { a_ref[c] };
                    *e = self.emit(c, a_emit, opts.moment_anisotropy);
                    let w = *pc * e.path / h;
                    *jc += w * per_channel(a_ref[c], |ac| hg(self.mu[c], clamp_a(ac * g)));
                    (arrived, escaped_at(c, e, *pc), vac)
                })
                .reduce(|| (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO), |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2));
            if progress.cancelled() {
                return Err(Error::Cancelled);
            }
            // What left `before` and neither arrived in a cell nor left the grid was absorbed.
            absorbed += (before - esc_next - arrived).max(Vec3::ZERO);
            escaped += esc_next + vac;
            esc_next = esc;
            let sum = arrived - vac;
            before = sum;
            remaining = sum;
            // Progress: iterations, or orders of magnitude of the residual, whichever is ahead.
            let decades = (remaining / injected.max(Vec3::splat(1e-30))).max_element().max(1e-12).log10();
            let frac = (iterations as f32 / self.max_iterations as f32).max(decades / self.residual_threshold.max(1e-12).log10());
            if !progress.update("pop propagation", frac.clamp(0.0, 1.0)) {
                return Err(Error::Cancelled);
            }
        }
        Ok(PropagationStats {
            iterations,
            injected: injected.to_array(),
            escaped: escaped.to_array(),
            absorbed: absorbed.to_array(),
            residual: remaining.to_array(),
            residual_anisotropy: mean_anisotropy(&p, &a).to_array(),
            remaining: if opts.keep_remaining { p } else { Vec::new() },
        })
    }
}

/// Energy-weighted mean anisotropy of packets `p` with anisotropies `a`, per channel.
pub fn mean_anisotropy(p: &[Vec3], a: &[Vec3]) -> Vec3 {
    let (pa, sum) = p.iter().zip(a).fold((Vec3::ZERO, Vec3::ZERO), |(pa, sum), (p, a)| (pa + *p * *a, sum + *p));
    Vec3::select(sum.cmpgt(Vec3::ZERO), pa / sum.max(Vec3::splat(1e-30)), Vec3::ZERO)
}

#[cfg(test)]
mod moment_tests {
    use super::*;

    /// The closed-form first moment against a midpoint-rule integral of cos p(cos) (20000
    /// steps: error ~1e-7 for |g| <= 0.95, bound 1e-4 for f32 rounding), and over the whole
    /// sphere it is g itself.
    #[test]
    fn hg_cone_moment_is_the_first_moment() {
        for g in [-0.9f32, -0.3, 0.0, 0.2, 0.7, 0.95] {
            let whole = hg_cone_moment(-1.0, 1.0, g);
            assert!((whole - g).abs() < 1e-4, "g {g}: whole-sphere moment {whole}");
            for (lo, hi) in [(COS_45, 1.0), (-COS_45, COS_45), (-1.0, -COS_45)] {
                let n = 20_000;
                let num: f64 = (0..n)
                    .map(|i| {
                        let c = lo as f64 + (hi - lo) as f64 * (i as f64 + 0.5) / n as f64;
                        let u = 1.0 + (g * g) as f64 - 2.0 * g as f64 * c;
                        c * (1.0 - (g * g) as f64) / (2.0 * u.powf(1.5))
                    })
                    .sum::<f64>()
                    * (hi - lo) as f64
                    / n as f64;
                let m = hg_cone_moment(lo, hi, g);
                assert!((m as f64 - num).abs() < 1e-4, "g {g} [{lo}, {hi}]: {m} vs numerical {num}");
            }
        }
    }

    /// Split into front, sides and back with their own mean cosines, a lobe keeps its net
    /// flux: front a_f + 4 side a_s + back a_b = a (bound 1e-4: f32 rounding); the front part
    /// points forwards and the back part backwards, whatever a.
    #[test]
    fn lobe_moments_keep_the_net_flux() {
        for a in [-0.8f32, -0.2, 0.0, 0.3, 0.9, 0.99] {
            let av = Vec3::splat(a);
            let (f, s, b) = lobe_fractions(av);
            let (af, as_, ab) = lobe_moments(av, f, s, b);
            let flux = f.x * af.x + 4.0 * s.x * as_.x + b.x * ab.x;
            assert!((flux - a).abs() < 1e-4, "a {a}: net flux {flux}");
            assert!(af.x > COS_45 - 1e-4 && ab.x < -COS_45 + 1e-4 && as_.x.abs() < COS_45, "a {a}: {af} {as_} {ab}");
        }
    }

    /// The path one iteration stands for is positive for backward lobes too (a < 0: negative
    /// g, or the back part of a lobe with `moment_anisotropy`); the drift-matched path of a
    /// lobe and of its mirror image are the same.
    #[test]
    fn path_factor_is_positive_for_backward_lobes() {
        let (ss, sa) = (Vec3::splat(5.0), Vec3::splat(0.1));
        for a in [0.9f32, 0.5, 0.1] {
            let k = |a: f32| {
                let (f, _, b) = lobe_fractions(Vec3::splat(a));
                path_factor(true, f, b, Vec3::splat(a), ss, sa, 0.9, 0.1).x
            };
            assert!(k(-a) > 0.0 && (k(-a) - k(a)).abs() < 1e-5, "a {a}: kappa {} vs mirrored {}", k(a), k(-a));
        }
    }
}
