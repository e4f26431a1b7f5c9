//! The geometric tail of a solve of many orders.
//!
//! Past its first orders, the light left in a thick medium is its slowest diffusion mode, which
//! each order scales by the same factor r (a channel's own: the albedo may be coloured). What
//! the orders still to come would add to J is then the next order's times 1 / (1 - r): one
//! sweep of U scaled by that factor adds it, in place of the tens or hundreds of orders that
//! would. It is taken once r has settled from order to order and the tail is a small share of
//! J, so that an error of a few percent in r moves J by a fraction of a percent. r is read off
//! the sums of J over the cells, in f64: an f32 sum of a large J jitters by more than a late
//! order adds. Engaged with coarse.rs's late orders (a solve predicted far beyond a usual
//! number of orders); a usual solve runs its orders to `epsilon`, the same to the bit.

use glam::{DVec3, Vec3};

/// r settled: it moved by less than this in every channel over the last order.
const SETTLED: f64 = 0.01;

/// The tail is taken when it is at most this share of J (in every channel that has light).
const SMALL_SHARE: f64 = 0.03;

/// Above this r the factor 1 / (1 - r) magnifies r's error too much: the orders go on.
const R_MAX: f64 = 0.995;

/// J's sum after each order, from the first order's J on.
pub struct Tail {
    sums: Vec<DVec3>,
    /// Index of the first sum from which order-to-order increments compare (a change of the
    /// sweeper's directions changes an order's increment by a step).
    since: usize,
}

fn sum(j: &[Vec3]) -> DVec3 {
    j.iter().fold(DVec3::ZERO, |a, v| a + v.as_dvec3())
}

impl Tail {
    /// Starts from J of the first order.
    pub fn new(j: &[Vec3]) -> Self {
        Tail { sums: vec![sum(j)], since: 0 }
    }

    /// J after one more order.
    pub fn push(&mut self, j: &[Vec3]) {
        self.sums.push(sum(j));
    }

    /// The next orders run over other directions: their increments start a new run of ratios.
    pub fn restart(&mut self) {
        self.since = self.sums.len() - 1;
    }

    /// The ratio r of the last two orders' increments per channel (0 in a channel with no
    /// light left), when it moved by less than `SETTLED` over the last order in every channel.
    pub fn settled(&self) -> Option<DVec3> {
        let n = self.sums.len();
        // Three increments since the restart: two ratios to compare.
        if n < self.since + 4 {
            return None;
        }
        let d = |k: usize| self.sums[n - k] - self.sums[n - k - 1];
        let (d1, d2, d3) = (d(1), d(2), d(3));
        let mut r = DVec3::ZERO;
        for c in 0..3 {
            if d2[c] <= 0.0 {
                // No light in this channel (or none left): one more order adds nothing.
                if d1[c] > 0.0 {
                    return None;
                }
                continue;
            }
            if d3[c] <= 0.0 {
                return None;
            }
            let (now, before) = (d1[c] / d2[c], d2[c] / d3[c]);
            if !(0.0..=R_MAX).contains(&now) || (now - before).abs() > SETTLED {
                return None;
            }
            r[c] = now;
        }
        Some(r)
    }

    /// The factor (per channel) to scale U of the last order by, so that one more sweep adds
    /// every order still to come; None until r has settled and the tail is small.
    pub fn factor(&self) -> Option<Vec3> {
        let r = self.settled()?;
        let n = self.sums.len();
        let (d1, total) = (self.sums[n - 1] - self.sums[n - 2], self.sums[n - 1]);
        // What the orders after the last would add: d1 (r + r^2 + ...).
        let tail = d1 * r / (DVec3::ONE - r);
        (0..3).all(|c| tail[c] <= SMALL_SHARE * total[c]).then(|| (DVec3::ONE / (DVec3::ONE - r)).as_vec3())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tail_of(increments: &[[f32; 3]]) -> Tail {
        let mut j = vec![Vec3::splat(10.0)];
        let mut t = Tail::new(&j);
        for d in increments {
            j[0] += Vec3::from(*d);
            t.push(&j);
        }
        t
    }

    /// A geometric series gives the factor of its ratio once its tail is small, per channel; a
    /// ratio still moving or a tail still large gives none.
    #[test]
    fn lpm_tail_is_taken_only_settled_and_small() {
        let geometric = |r: f32, n: usize| (1..=n).map(|k| [r.powi(k as i32), 0.5 * (r * 0.9).powi(k as i32), 0.0]).collect::<Vec<_>>();
        // r 0.8: after 12 orders the tail is 0.8^13 / 0.2 = 0.27 of a J near 13.
        let f = tail_of(&geometric(0.8, 12)).factor().expect("settled and small");
        assert!((f.x - 5.0).abs() < 1e-3 && (f.y - 1.0 / (1.0 - 0.72)).abs() < 1e-3 && f.z == 1.0, "{f}");
        // The same series two orders in: too few increments; with a large tail: none.
        assert!(tail_of(&geometric(0.8, 2)).factor().is_none());
        assert!(tail_of(&geometric(0.98, 12)).factor().is_none(), "a tail of 0.98^13 / 0.02 is far over 3% of J");
        // A ratio that moves by 0.05 an order.
        let moving: Vec<[f32; 3]> = [1.0f32, 0.6, 0.39, 0.27].iter().map(|v| [*v, 0.0, 0.0]).collect();
        assert!(tail_of(&moving).factor().is_none());
        // After a restart the ratios start anew.
        let mut t = tail_of(&geometric(0.8, 12));
        t.restart();
        assert!(t.factor().is_none());
    }
}
