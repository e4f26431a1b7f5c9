//! Cache tallies in fixed point (integers with 64 fraction bits), the form in which batches
//! and generations are summed and the temporal ring adds its newest generation and removes its
//! oldest (ring.rs). Integer sums are exact and independent of order, so:
//! - a ring that has replaced all its generations holds bit for bit the tallies a one-off
//!   solve of the same generations would (float sums drift with every add-and-remove);
//! - batches may be summed in any order (threads, or GPU atomics) and still agree exactly.
//!
//! Range: 2^-64 (5e-20) resolution and magnitudes below 2^63 (9e18) in i128. A batch's f32
//! cell value of 2^-40 or more converts exactly (its 24-bit mantissa ends above 2^-64);
//! deposits are each photon's power (emitted power / photons) x weight x rho / majorant, far
//! inside that range for any scene in metres and watts.

use glam::Vec3;

use super::cache::{Cache, Cell};

const ONE: f64 = 18_446_744_073_709_551_616.0; // 2^64

#[inline]
fn fix(v: f32) -> i128 {
    // f32 x 2^64 is exact in f64; the cast saturates (never wraps) beyond the range.
    (v as f64 * ONE).round() as i128
}

#[inline]
pub fn unfix(v: i128) -> f64 {
    v as f64 / ONE
}

/// A fixed-point value with 64 fraction bits from `v` units of `unit` (an integer count of
/// `unit`, as the GPU's 64-bit atomics sum them: volscatter-gpu photon_grid). Exact while the
/// result is within range and `unit` >= 2^-64 / 2^24 (its mantissa shifted stays an integer);
/// below that it rounds to the nearest 2^-64.
pub fn fix_units(v: i64, unit: f32) -> i128 {
    if v == 0 || unit == 0.0 || !unit.is_finite() {
        return 0;
    }
    // unit = m 2^e with an integer mantissa m < 2^24.
    let bits = unit.abs().to_bits();
    let (exp, frac) = ((bits >> 23) as i32, (bits & 0x7f_ffff) as i128);
    let (m, e) = if exp == 0 { (frac, -149) } else { (frac | 0x80_0000, exp - 150) };
    let m = if unit < 0.0 { -m } else { m };
    let shift = e + 64;
    let p = v as i128 * m;
    if shift >= 0 {
        p.saturating_mul(1i128 << shift.min(126))
    } else {
        // Round half away from zero, like `fix`.
        let s = (-shift).min(127) as u32;
        let half = 1i128 << (s - 1);
        if p >= 0 { (p + half) >> s } else { -((-p + half) >> s) }
    }
}

#[inline]
fn fix3(v: Vec3) -> [i128; 3] {
    [fix(v.x), fix(v.y), fix(v.z)]
}

pub fn unfix3(v: &[i128; 3]) -> Vec3 {
    Vec3::new(unfix(v[0]) as f32, unfix(v[1]) as f32, unfix(v[2]) as f32)
}

/// One cell's tallies in fixed point (cache.rs `Cell`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FixedCell {
    pub flux: [i128; 3],
    pub moment: [i128; 3],
    pub weight: i128,
    pub order: i128,
    pub count: u64,
}

impl FixedCell {
    fn of(c: &Cell) -> Self {
        FixedCell { flux: fix3(c.flux), moment: fix3(c.moment), weight: fix(c.weight), order: fix(c.order), count: c.count as u64 }
    }

    fn add(&mut self, o: &FixedCell) {
        for k in 0..3 {
            self.flux[k] += o.flux[k];
            self.moment[k] += o.moment[k];
        }
        self.weight += o.weight;
        self.order += o.order;
        self.count += o.count;
    }

    fn sub(&mut self, o: &FixedCell) {
        for k in 0..3 {
            self.flux[k] -= o.flux[k];
            self.moment[k] -= o.moment[k];
        }
        self.weight -= o.weight;
        self.order -= o.order;
        self.count -= o.count;
    }
}

/// A whole cache's tallies in fixed point, on the cells of the `Cache` they came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FixedTallies {
    pub cells: Vec<FixedCell>,
}

impl FixedTallies {
    pub fn zeros(len: usize) -> Self {
        FixedTallies { cells: vec![FixedCell::default(); len] }
    }

    /// The sum of `caches` (f32 batch tallies on one frame), exact and order-independent.
    pub fn sum_of(caches: &[&Cache]) -> Self {
        let mut out = FixedTallies::zeros(caches.first().map_or(0, |c| c.cells.len()));
        for c in caches {
            for (o, cell) in out.cells.iter_mut().zip(&c.cells) {
                o.add(&FixedCell::of(cell));
            }
        }
        out
    }

    /// `sum_of` in parallel slabs of cells, reading the cancel flag per slab (32 batch caches
    /// of 128^3 cells take a core about half a second): cut short, the sum is partial and the
    /// caller, which checks the flag, discards it. Exact and order-independent as `sum_of`.
    pub fn sum_of_cancellable(caches: &[&Cache], progress: &dyn crate::stages::Progress) -> Self {
        use rayon::prelude::*;
        const SLAB: usize = 1 << 14;
        let mut out = FixedTallies::zeros(caches.first().map_or(0, |c| c.cells.len()));
        out.cells.par_chunks_mut(SLAB).enumerate().for_each(|(i, slab)| {
            if progress.cancelled() {
                return;
            }
            for c in caches {
                for (o, cell) in slab.iter_mut().zip(&c.cells[i * SLAB..]) {
                    o.add(&FixedCell::of(cell));
                }
            }
        });
        out
    }

    pub fn add(&mut self, o: &FixedTallies) {
        for (a, b) in self.cells.iter_mut().zip(&o.cells) {
            a.add(b);
        }
    }

    pub fn sub(&mut self, o: &FixedTallies) {
        for (a, b) in self.cells.iter_mut().zip(&o.cells) {
            a.sub(b);
        }
    }

    /// These tallies, kept on cache `from`, moved onto cache `to` (another frame: a VDB
    /// sequence whose bounds changed): each cell's integers go whole to the cell of `to`
    /// nearest its centre, so nothing is created; cells whose centre falls outside `to` are
    /// dropped (light of a part of the medium that is gone).
    pub fn moved(&self, from: &Cache, to: &Cache) -> Self {
        let mut out = FixedTallies::zeros(to.cells.len());
        let [nx, ny, _] = from.frame.dims;
        for (idx, cell) in self.cells.iter().enumerate() {
            let idx = idx as u32;
            let centre = from.frame.position(idx % nx, (idx / nx) % ny, idx / (nx * ny));
            if let Some(j) = to.cell_of(centre) {
                out.cells[j].add(cell);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Adding then removing in fixed point returns exactly what was there, where f32 (or f64)
    /// sums drift: the property the ring's exactness rests on.
    #[test]
    fn add_then_remove_is_exact() {
        let a = Cell { flux: Vec3::new(0.1, 3.0e-7, 12345.678), moment: Vec3::new(-0.3, 0.2, 1e-9), weight: 0.7, order: 1.3, count: 3 };
        let b = Cell { flux: Vec3::new(1e-3, 7.77, 0.5), moment: Vec3::new(0.9, -4.0, 2.0), weight: 5.5, order: 2.0, count: 9 };
        let mut sum = FixedCell::of(&a);
        sum.add(&FixedCell::of(&b));
        sum.sub(&FixedCell::of(&a));
        assert_eq!(sum, FixedCell::of(&b));
        // The values come back to f32 exactly (2^-40 and above convert without rounding).
        assert_eq!(unfix3(&sum.flux), b.flux);
        assert_eq!(unfix(sum.weight) as f32, b.weight);
        // In f32 the same round trip is not exact: what the integers avoid.
        assert_ne!((a.flux.x + b.flux.x) - a.flux.x, b.flux.x);
    }

    /// Counts of a unit land on the same fixed point as the f32 value they stand for, where
    /// that is exact (units from 2^-40, as the GPU uses them), and round to 2^-64 below.
    #[test]
    fn units_convert_exactly() {
        for (v, unit) in [(3i64, 0.75f32), (-5, 0.0009765625), (1 << 40, 2.0f32.powi(-32)), (-(1 << 20), 1.5e-9)] {
            assert_eq!(fix_units(v, unit), fix(v as f32 * unit), "{v} x {unit}");
        }
        assert_eq!(fix_units(1, 2.0f32.powi(-70)), 0);
        assert_eq!(fix_units(3, 2.0f32.powi(-65)), 2);
        assert_eq!(fix_units(-3, 2.0f32.powi(-65)), -2);
        assert_eq!(fix_units(7, 0.0), 0);
    }
}
