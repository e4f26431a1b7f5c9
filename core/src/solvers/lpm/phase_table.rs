//! The phase table F (Eq. 5) from the medium's Henyey-Greenstein function, between the
//! propagation bins: `fine[j][i]` = (1 / |Omega_j|) integral over Omega_j integral over Omega_i
//! p(w . w') dw' dw, the mean over outgoing bin j of the light scattered out of bin i (so
//! sum_i fine[j][i] = 1, and |Omega_j| fine[j][i] is the paper's F, whose rows sum to the
//! solid angle |Omega_j|). By a 4 x 4 sub-sample quadrature of each bin pair; each row is then
//! normalised to 1 exactly so that scattering conserves energy whatever the quadrature's
//! error (measured in tests.rs).
//!
//! `storage[d][i]`: the same mean over a storage bin d (what collect.rs adds to U_d).
//!
//! `view`: the rows J towards the camera is read from (collect.rs), one per sub-sample of each
//! bin (`view_rows`), always the true phase function's: under the delta-M split (delta_m.rs)
//! `fine` and `storage` hold the residual lobe's.

use glam::Vec3;
use rayon::prelude::*;

use super::directions::{Directions, SUBS};
use crate::error::Result;
use crate::phase::{hg, hg_cone_fraction};

/// The phase function the propagated orders scatter with: Henyey-Greenstein of parameter `g`,
/// its forward peak flattened above the cosine `cap` (1: the whole lobe) and the rest scaled
/// to integrate to 1. Flattened, the lobe keeps the true phase function's sideways and
/// backward scattering, which the delta-M split's residual HG overstates (delta_m.rs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub g: f32,
    pub cap: f32,
    scale: f32,
}

impl Lobe {
    pub fn hg(g: f32) -> Self {
        Lobe { g, cap: 1.0, scale: 1.0 }
    }

    /// HG of `g` flattened above the cosine `cap`.
    pub fn flattened(g: f32, cap: f32) -> Self {
        Lobe { g, cap, scale: 1.0 / (1.0 - peak_fraction(g, cap)) }
    }

    /// The share of the HG lobe above its value at `cap` (what flattening takes off).
    pub fn peak(&self) -> f32 {
        if self.cap >= 1.0 { 0.0 } else { peak_fraction(self.g, self.cap) }
    }

    #[inline]
    pub fn eval(&self, mu: f32) -> f32 {
        // HG rises with mu for g > 0: the flattened lobe is its value at min(mu, cap).
        if self.cap >= 1.0 { hg(mu, self.g) } else { self.scale * hg(mu.min(self.cap), self.g) }
    }
}

/// The share of HG(`g`) above its own value at the cosine `cap`: the cone's mass less the
/// cone's solid angle times p(cap).
pub fn peak_fraction(g: f32, cap: f32) -> f32 {
    let cone = hg_cone_fraction(cap, g) as f64;
    (cone - 2.0 * std::f64::consts::PI * (1.0 - cap as f64) * hg(cap, g) as f64).max(0.0) as f32
}

pub struct PhaseTable {
    pub n: usize,
    pub m: usize,
    /// n x n, row j = outgoing bin.
    pub fine: Vec<f32>,
    /// m x n, row d = outgoing storage bin.
    pub storage: Vec<f32>,
    /// Row sums of `fine` times |Omega_j| before normalisation (the paper's F rows), for the
    /// tests.
    pub raw_row_solid_angle: Vec<f32>,
    /// Rows towards the viewer, one per sub-sample of each bin (`view_rows`), n x SUBS x n:
    /// the true phase function's. None: `fine`'s rows (tests).
    pub view: Option<Vec<f32>>,
    /// The phase function the table was made from.
    pub lobe: Lobe,
}

impl PhaseTable {
    pub fn new(dirs: &Directions, g: f32) -> Result<Self> {
        Self::from_lobe(dirs, Lobe::hg(g))
    }

    /// The medium's own table (HG of `g`) with its rows towards the viewer (`view_rows`): what
    /// a solve scatters with, and what J is read from under the delta-M split too.
    pub fn true_phase(dirs: &Directions, g: f32) -> Result<Self> {
        let view = Self::view_rows(dirs, Lobe::hg(g))?;
        Ok(Self::new(dirs, g)?.with_view(view))
    }

    pub fn from_lobe(dirs: &Directions, lobe: Lobe) -> Result<Self> {
        let n = dirs.len();
        let m = dirs.storage_len();
        let count = crate::budget::check_elements::<f32>("lpm phase table (directions^2)", (n as u64) * (n as u64 + m as u64))?;
        let mut fine = vec![0.0f32; count - m * n];
        let raw: Vec<f32> = fine
            .par_chunks_mut(n)
            .enumerate()
            .map(|(j, row)| {
                for (i, out) in row.iter_mut().enumerate() {
                    let mut sum = 0.0f64;
                    for &(wj, oj) in &dirs.sub[j] {
                        for &(wi, oi) in &dirs.sub[i] {
                            sum += (oj * oi * lobe.eval(wj.dot(wi))) as f64;
                        }
                    }
                    *out = (sum / dirs.dirs[j].solid_angle as f64) as f32;
                }
                let total: f64 = row.iter().map(|&x| x as f64).sum();
                for x in row.iter_mut() {
                    *x = (*x as f64 / total) as f32;
                }
                (total * dirs.dirs[j].solid_angle as f64) as f32
            })
            .collect();
        let mut storage = vec![0.0f32; m * n];
        for (j, dj) in dirs.dirs.iter().enumerate() {
            let w = dj.solid_angle / dirs.storage_solid_angle[dj.storage];
            for i in 0..n {
                storage[dj.storage * n + i] += w * fine[j * n + i];
            }
        }
        Ok(PhaseTable { n, m, fine, storage, raw_row_solid_angle: raw, view: None, lobe })
    }

    /// The table whose scattering, as the propagation sees it, keeps the phase function's mean
    /// cosine `g`. Averaging over the bins (each pair's sub-samples, then a storage bin's
    /// directions sharing one value) widens the lobe: the table made from `g` itself sends the
    /// light on with a smaller mean cosine, so in a thick medium it diffuses back out too soon
    /// (too bright from the lit side). The HG parameter is raised until the table's
    /// `mean_cosine` is `g` (found once per process for a set of bins and `g`). A sun's first
    /// scattering into the storage bins (lights.rs) takes the same parameter, so that the exact
    /// first order and the boundary sweep through the table stay one method.
    pub fn keeping_mean_cosine(dirs: &Directions, g: f32) -> Result<Self> {
        if g.abs() < 1e-3 {
            return Self::new(dirs, g);
        }
        Self::new(dirs, matched_parameter(dirs, g)?)
    }

    /// The mean cosine between light arriving along a bin and the light its scattering sends
    /// on (each outgoing direction carrying its storage bin's U), over incoming bins weighted by
    /// their solid angle (isotropic incoming radiance).
    pub fn mean_cosine(&self, dirs: &Directions) -> f64 {
        let n = self.n;
        let (mut num, mut den) = (0f64, 0f64);
        for (i, di) in dirs.dirs.iter().enumerate() {
            for dj in &dirs.dirs {
                let e = (self.storage[dj.storage * n + i] * dj.solid_angle * di.solid_angle) as f64;
                num += e * dj.w.dot(di.w) as f64;
                den += e;
            }
        }
        num / den.max(f64::MIN_POSITIVE)
    }

    /// Mean over storage bin `d` of p(w_out . w) for light travelling along unit `w` (a
    /// collimated beam's first scattering), by the bin's sub-samples.
    pub fn storage_mean_towards(dirs: &Directions, d: usize, w: Vec3, lobe: Lobe) -> f32 {
        let mut sum = 0.0f32;
        for (j, dj) in dirs.dirs.iter().enumerate() {
            if dj.storage == d {
                sum += dirs.sub[j].iter().map(|&(wj, oj)| oj * lobe.eval(wj.dot(w))).sum::<f32>();
            }
        }
        sum / dirs.storage_solid_angle[d]
    }

    /// The same from the table (light along any direction of bin `i`): cheap, for the many
    /// emitter-to-cell directions.
    #[inline]
    pub fn storage_mean_from_bin(&self, dirs: &Directions, d: usize, i: usize) -> f32 {
        self.storage[d * self.n + i] / dirs.dirs[i].solid_angle
    }

    /// The same table with `view` (`view_rows`) as the rows towards the viewer.
    pub fn with_view(self, view: Vec<f32>) -> Self {
        debug_assert_eq!(view.len(), self.n * self.n * SUBS);
        PhaseTable { view: Some(view), ..self }
    }

    /// The rows towards the viewer of phase function `lobe`, one per sub-sample of each bin
    /// (`Directions::view_index`): row (j, s) holds, for each bin i, the share of light arriving
    /// along bin i that scatters into the sub-sample's direction. A bin's mean over its outgoing
    /// directions blurs a lobe narrower than a bin (g 0.9: about 6 degrees, against a preview
    /// bin's 18) across the bin, so J depended on where in its bin the camera's direction fell
    /// (docs/solvers/lpm.md, "The view rows").
    pub fn view_rows(dirs: &Directions, lobe: Lobe) -> Result<Vec<f32>> {
        let n = dirs.len();
        let count = crate::budget::check_elements::<f32>("lpm view table (directions^2 x sub-samples)", (n * SUBS) as u64 * n as u64)?;
        let mut rows = vec![0.0f32; count];
        rows.par_chunks_mut(n).enumerate().for_each(|(r, row)| {
            let w = dirs.sub[r / SUBS][r % SUBS].0;
            let mut total = 0.0f64;
            for (i, out) in row.iter_mut().enumerate() {
                let v: f64 = dirs.sub[i].iter().map(|&(wi, oi)| (oi * lobe.eval(w.dot(wi))) as f64).sum();
                *out = v as f32;
                total += v;
            }
            for x in row.iter_mut() {
                *x = (*x as f64 / total) as f32;
            }
        });
        Ok(rows)
    }

    /// The rows towards the viewer, indexed by `Directions::view_index`: `view`, or without
    /// it each bin's `fine` row for all its sub-samples.
    pub fn view_table(&self) -> std::borrow::Cow<'_, [f32]> {
        match &self.view {
            Some(v) => std::borrow::Cow::Borrowed(v),
            None => std::borrow::Cow::Owned((0..self.n * SUBS).flat_map(|r| self.fine_row(r / SUBS).iter().copied()).collect()),
        }
    }

    /// Row `r` (`Directions::view_index`) of `view_table`.
    #[inline]
    pub fn view_row(&self, r: usize) -> &[f32] {
        match &self.view {
            Some(v) => &v[r * self.n..(r + 1) * self.n],
            None => self.fine_row(r / SUBS),
        }
    }

    #[inline]
    pub fn fine_row(&self, j: usize) -> &[f32] {
        &self.fine[j * self.n..(j + 1) * self.n]
    }

    #[inline]
    pub fn storage_row(&self, d: usize) -> &[f32] {
        &self.storage[d * self.n..(d + 1) * self.n]
    }
}

/// What is fitted to a set of bins and a g: the HG parameter of `keeping_mean_cosine`, or the
/// cap of a flattened lobe.
#[derive(Clone, Copy, PartialEq)]
enum Fitted {
    Parameter,
    Cap,
}

/// `find()`, once per process for `what`, the bins and `g` (a session's frames and the coarse
/// late orders ask again; each search builds several tables).
fn fitted_once(what: Fitted, dirs: &Directions, g: f32, find: impl FnOnce() -> Result<f32>) -> Result<f32> {
    /// (what, directions a face side, storage bins a face side, g's bits) -> the value.
    type Found = Vec<((Fitted, usize, usize, u32), f32)>;
    static FOUND: std::sync::Mutex<Found> = std::sync::Mutex::new(Vec::new());
    let key = (what, dirs.k, dirs.s, g.to_bits());
    if let Some(&(_, t)) = FOUND.lock().unwrap_or_else(|e| e.into_inner()).iter().find(|(k, _)| *k == key) {
        return Ok(t);
    }
    let t = find()?;
    FOUND.lock().unwrap_or_else(|e| e.into_inner()).push((key, t));
    Ok(t)
}

/// The HG parameter keeping the mean cosine `g` on `dirs`' bins (`keeping_mean_cosine`).
fn matched_parameter(dirs: &Directions, g: f32) -> Result<f32> {
    fitted_once(Fitted::Parameter, dirs, g, || raise_until(g, |t| Ok(PhaseTable::new(dirs, t)?.mean_cosine(dirs))))
}

/// The cosine above which HG(`g`) is flattened so that the propagation, through `dirs`'
/// bins, carries light on with the mean cosine `g`: the peak's share goes straight on (mean
/// cosine 1), the flattened rest with the table's `mean_cosine`.
pub fn flattening_cap(dirs: &Directions, g: f32) -> Result<f32> {
    // The transport's mean cosine less g against the cap's angle: it rises from the bins'
    // loss at no flattening (below g) to nearly 1 at a flattening over the whole sphere.
    let transport = |angle: f64| -> Result<f64> {
        let lobe = Lobe::flattened(g, angle.cos() as f32);
        let f = lobe.peak() as f64;
        Ok(f + (1.0 - f) * PhaseTable::from_lobe(dirs, lobe)?.mean_cosine(dirs) - g as f64)
    };
    fitted_once(Fitted::Cap, dirs, g, || Ok(rising_root(1e-3, std::f64::consts::PI, transport)?.cos() as f32))
}

/// The parameter t between `g` and +-0.995 (on `g`'s side) where `mean(t)`, which rises with t,
/// is `g`; the end itself when the mean cannot reach `g` there.
fn raise_until(g: f32, mut mean: impl FnMut(f32) -> Result<f64>) -> Result<f32> {
    let (a, b) = if g > 0.0 { (g as f64, 0.995) } else { (-0.995, g as f64) };
    Ok(rising_root(a, b, |t| Ok(mean(t as f32)? - g as f64))? as f32)
}

/// Where `h`, which rises from `a` to `b`, crosses 0 (to 2e-4); `a` itself when h(a) >= 0, `b`
/// when h(b) <= 0. Regula falsi (Illinois): h is smooth, and each evaluation builds a table.
fn rising_root(mut a: f64, mut b: f64, mut h: impl FnMut(f64) -> Result<f64>) -> Result<f64> {
    let (mut fa, mut fb) = (h(a)?, h(b)?);
    if fa >= 0.0 {
        return Ok(a);
    }
    if fb <= 0.0 {
        return Ok(b);
    }
    let mut side = 0;
    for _ in 0..20 {
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = h(c)?;
        if fc.abs() < 2e-4 {
            return Ok(c);
        }
        if fc < 0.0 {
            (a, fa) = (c, fc);
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            (b, fb) = (c, fc);
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    Ok(0.5 * (a + b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's F rows (before our normalisation) sum to their bin's solid angle, since
    /// the phase function integrates to 1: within 0.5% at g 0, 0.6 and within 2% at 0.9,
    /// where the 4 x 4 sub-samples resolve the lobe (width ~ 1 - g rad) only roughly.
    /// Normalised rows sum to 1 to rounding, storage rows too.
    #[test]
    fn phase_table_rows_sum_to_solid_angle() {
        let dirs = Directions::new(5, 2);
        for (g, tol) in [(0.0f32, 0.005f32), (0.6, 0.005), (0.9, 0.02)] {
            let t = PhaseTable::new(&dirs, g).unwrap();
            let worst = t
                .raw_row_solid_angle
                .iter()
                .zip(&dirs.dirs)
                .map(|(r, d)| (r / d.solid_angle - 1.0).abs())
                .fold(0.0f32, f32::max);
            eprintln!("g {g}: worst |row / solid angle - 1| = {worst:.5}");
            assert!(worst < tol, "g {g}: {worst}");
            for j in 0..t.n {
                let s: f32 = t.fine_row(j).iter().sum();
                assert!((s - 1.0).abs() < 1e-4, "row {j} {s}");
            }
            for d in 0..t.m {
                let s: f32 = t.storage_row(d).iter().sum();
                assert!((s - 1.0).abs() < 1e-4, "storage row {d} {s}");
            }
            // Isotropic: every entry is the incoming bin's share of the sphere.
            if g == 0.0 {
                for i in 0..t.n {
                    let want = dirs.dirs[i].solid_angle / (4.0 * std::f32::consts::PI);
                    assert!((t.fine[i] - want).abs() < 1e-4 * want.max(1e-3) + 1e-6);
                }
            }
        }
    }

    /// The table made from g sends scattered light on with a smaller mean cosine than g (the
    /// bins widen the lobe); `keeping_mean_cosine` raises its parameter until the mean cosine
    /// is g again, to 1e-3, on the presets' bins (draft 2 x 2 a face, preview 5 x 5, final 6 x 6
    /// with 3 x 3 storage bins a face), for the residual lobes of g 0.6-0.9 under delta-M and
    /// a backward g. Isotropic tables are left as they are.
    #[test]
    fn matched_table_keeps_the_mean_cosine() {
        for (k, s) in [(2, 1), (5, 1), (6, 3)] {
            let dirs = Directions::new(k, s);
            for g in [0.6f32 / 1.6, 0.9 / 1.9, -0.3] {
                let plain = PhaseTable::new(&dirs, g).unwrap().mean_cosine(&dirs);
                let t = PhaseTable::keeping_mean_cosine(&dirs, g).unwrap();
                let kept = t.mean_cosine(&dirs);
                eprintln!("{k} x {k} a face, {s} x {s} storage: g {g:.3}: plain table {plain:.3}, parameter {:.3} keeps {kept:.4}", t.lobe.g);
                assert!(plain.abs() < g.abs() as f64 - 0.01, "the plain table should lose some of g: {plain}");
                assert!((kept - g as f64).abs() < 1e-3, "{kept} vs {g}");
            }
            let iso = PhaseTable::keeping_mean_cosine(&dirs, 0.0).unwrap();
            assert_eq!(iso.lobe.g, 0.0);
            assert!(iso.mean_cosine(&dirs).abs() < 1e-4);
        }
    }

    /// The flattened lobe is a phase function (integrates to 1), equals the true HG scaled by
    /// 1 / (1 - f) below its cap, and f is the mass above the cap's value (midpoint rules over
    /// mu, 2e5 steps: 1e-4 is their error at g 0.9).
    #[test]
    fn flattened_lobe_keeps_the_true_lobe_below_its_cap() {
        for (g, angle) in [(0.9f32, 10.0f32), (0.9, 45.0), (0.6, 25.0)] {
            let cap = angle.to_radians().cos();
            let lobe = Lobe::flattened(g, cap);
            let f = lobe.peak();
            let n = 200_000;
            let (mut total, mut above) = (0f64, 0f64);
            for i in 0..n {
                let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
                let dmu = 2.0 / n as f64;
                total += 2.0 * std::f64::consts::PI * lobe.eval(mu as f32) as f64 * dmu;
                above += 2.0 * std::f64::consts::PI * (hg(mu as f32, g) - hg(cap, g)).max(0.0) as f64 * dmu;
                if (mu as f32) < cap {
                    let want = hg(mu as f32, g) / (1.0 - f);
                    assert!((lobe.eval(mu as f32) - want).abs() <= 1e-5 * want, "g {g} mu {mu}");
                }
            }
            assert!((total - 1.0).abs() < 1e-3, "g {g} cap {angle}: integral {total}");
            assert!((above - f as f64).abs() < 1e-3, "g {g} cap {angle}: f {f} vs {above}");
        }
        assert_eq!(Lobe::hg(0.9).peak(), 0.0);
    }

    /// The fitted cap keeps the transport's mean cosine through the bins, f + (1 - f) x the
    /// flattened table's, at g (to the search's 2e-4, with 1e-3 for the table's rounding), on
    /// the preview's and the final preset's bins; more bins leave more of the lobe below it.
    #[test]
    fn flattening_cap_keeps_the_transport_mean_cosine() {
        let mut caps = Vec::new();
        for (k, s) in [(5, 1), (6, 3)] {
            let dirs = Directions::new(k, s);
            for g in [0.6f32, 0.9] {
                let cap = flattening_cap(&dirs, g).unwrap();
                let lobe = Lobe::flattened(g, cap);
                let f = lobe.peak() as f64;
                let kept = f + (1.0 - f) * PhaseTable::from_lobe(&dirs, lobe).unwrap().mean_cosine(&dirs);
                eprintln!("{k} x {k} a face, {s} x {s} storage, g {g}: cap {:.1} degrees, f {f:.3}, mean cosine {kept:.4}", cap.acos().to_degrees());
                assert!((kept - g as f64).abs() < 1e-3, "{kept} vs {g}");
                assert!(cap < 1.0 && f > 0.0 && f < 1.0);
                caps.push(cap);
            }
        }
        assert!(caps[2] > caps[0] && caps[3] > caps[1], "finer bins should flatten less: {caps:?}");
    }

    /// The rows towards the viewer: each sums to 1; isotropic, every entry is the incoming
    /// bin's share of the sphere; at g 0.9 a bin's sub-sample rows differ (the lobe is narrower
    /// than a bin: the point of them) and their mean over the bin is its `fine` row, to the
    /// quadrature's 2% on the entries that carry 1% of a row or more.
    #[test]
    fn view_rows_resolve_the_lobe_within_a_bin() {
        let dirs = Directions::new(5, 1);
        let n = dirs.len();
        for g in [0.0f32, 0.9] {
            let t = PhaseTable::true_phase(&dirs, g).unwrap();
            let view = t.view_table();
            assert_eq!(view.len(), n * n * SUBS);
            for r in 0..n * SUBS {
                let row = t.view_row(r);
                assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-4, "row {r}");
                if g == 0.0 {
                    for (i, x) in row.iter().enumerate() {
                        let want = dirs.dirs[i].solid_angle / (4.0 * std::f32::consts::PI);
                        assert!((x - want).abs() < 1e-4 * want.max(1e-3) + 1e-6);
                    }
                }
            }
            if g == 0.9 {
                let j = 2 * 5 + 2; // the centre bin of face 0
                let (corner, centre) = (t.view_row(j * SUBS), t.view_row(j * SUBS + 5));
                let spread = (0..n).map(|i| (corner[i] - centre[i]).abs()).fold(0.0f32, f32::max);
                assert!(spread > 0.05, "sub-sample rows of one bin nearly equal at g 0.9: {spread}");
                let worst = (0..n)
                    .filter(|&i| t.fine_row(j)[i] >= 0.01)
                    .map(|i| {
                        let mean: f32 = (0..SUBS).map(|s| dirs.sub[j][s].1 * t.view_row(j * SUBS + s)[i]).sum::<f32>() / dirs.dirs[j].solid_angle;
                        (mean / t.fine_row(j)[i] - 1.0).abs()
                    })
                    .fold(0.0f32, f32::max);
                eprintln!("g 0.9: sub-sample rows of the centre bin differ by up to {spread:.3}; their mean against the bin's row: worst {worst:.4}");
                assert!(worst < 0.02, "{worst}");
            }
        }
    }
}
