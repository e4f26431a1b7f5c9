//! The temporal cache (paper 04, Sec. 3.2 and 4.2): a ring of m partial caches ("generations")
//! kept in a session. The cache a frame reconstructs from is the sum of the ring's m
//! generations, each traced with photons / m photons of power 1 / photons of its light's; a
//! one-off solve traces generations 0..m at once, a session's later frame traces the next
//! generation only and puts it in place of the oldest.
//!
//! Generation g always draws from the same random streams (trace.rs `run_generation`) and has
//! the same photon count (its slot g mod m's share), and the ring's sum is kept in integers
//! (fixed.rs), so once m frames have passed since the scene last changed the ring is bit for
//! bit the one-off solve of generations frame..frame + m (the test `ring_after_light_step_
//! equals_fresh_solve`). On a static scene, one generation of m is new each frame, so the
//! frame-to-frame change is sqrt(2 / m) of one full solve's noise (that is, 1 / sqrt(m) of the
//! difference between two seeds), where a one-off solve per frame with a new seed changes by
//! its full noise.
//!
//! A change of the medium's bounds (VDB sequences) changes the cache's frame: the kept
//! generations are moved cell by cell onto the new frame (fixed.rs `moved`) rather than
//! dropped, so a growing plume keeps its ring; they are then stale by up to m - 1 frames, as
//! for any other change of the scene.

use super::cache::Cache;
use super::fixed::FixedTallies;
use super::settings::PhotonGridSettings;
use super::trace::EnergyReport;

/// One partial cache: its index, the tallies of both lobes, and where its energy went.
pub struct Generation {
    pub index: u64,
    pub tallies: [FixedTallies; 2],
    pub energy: EnergyReport,
}

/// Photons of generation `g` out of `photons` split over `m` generations: the share of its
/// slot g mod m (shares differ by at most one photon and sum to `photons`).
pub fn photons_of(g: u64, photons: u32, m: u32) -> u32 {
    let (n, m) = (photons as u64, m as u64);
    let k = g % m;
    (n * (k + 1) / m - n * k / m) as u32
}

/// The session's ring (kept in `SessionState` as `KeptRing`).
pub struct Ring {
    /// The settings it was traced with (a session's are fixed; checked anyway, since the
    /// state may outlive a solver built with others).
    settings: PhotonGridSettings,
    /// The frame the generations' cells are on.
    cache: Cache,
    /// Generation g in slot g mod m.
    slots: Vec<Generation>,
    total: [FixedTallies; 2],
}

/// What a session keeps for `photon-grid`: the ring once a frame has been solved.
#[derive(Default)]
pub struct KeptRing(pub Option<Ring>);

impl Ring {
    /// A ring of `generations` (the m generations first..first + m, any order), traced on
    /// `cache`'s frame.
    pub fn new(settings: &PhotonGridSettings, cache: Cache, mut generations: Vec<Generation>) -> Ring {
        let m = settings.generations as u64;
        generations.sort_by_key(|g| g.index % m);
        let mut total = [FixedTallies::zeros(cache.cells.len()), FixedTallies::zeros(cache.cells.len())];
        for g in &generations {
            for (t, l) in total.iter_mut().zip(&g.tallies) {
                t.add(l);
            }
        }
        Ring { settings: settings.clone(), cache, slots: generations, total }
    }

    pub fn traced_with(&self, settings: &PhotonGridSettings) -> bool {
        self.settings == *settings && self.slots.len() == settings.generations as usize
    }

    /// The generation to trace next (one past the newest).
    pub fn next_generation(&self) -> u64 {
        self.slots.iter().map(|g| g.index).max().map_or(0, |i| i + 1)
    }

    /// Moves the ring onto `cache`'s frame if it is another (the medium's bounds changed).
    pub fn move_to(&mut self, cache: &Cache) {
        if cache.frame.dims == self.cache.frame.dims && cache.frame.index_to_world == self.cache.frame.index_to_world {
            return;
        }
        for g in &mut self.slots {
            for l in &mut g.tallies {
                *l = l.moved(&self.cache, cache);
            }
        }
        for t in &mut self.total {
            *t = t.moved(&self.cache, cache);
        }
        self.cache = cache.empty_like();
    }

    /// Puts `g` in place of the oldest generation (the one in its slot): the sum loses the
    /// old tallies and gains the new, in integers.
    pub fn replace(&mut self, g: Generation) {
        let slot = (g.index % self.settings.generations as u64) as usize;
        let old = &self.slots[slot];
        for ((t, o), n) in self.total.iter_mut().zip(&old.tallies).zip(&g.tallies) {
            t.sub(o);
            t.add(n);
        }
        self.slots[slot] = g;
    }

    pub fn cache(&self) -> &Cache {
        &self.cache
    }

    pub fn total(&self) -> &[FixedTallies; 2] {
        &self.total
    }

    /// The generations' energy, summed oldest first.
    pub fn energy(&self) -> EnergyReport {
        let mut order: Vec<&Generation> = self.slots.iter().collect();
        order.sort_by_key(|g| g.index);
        let mut e = EnergyReport::default();
        for g in order {
            e.add(&g.energy);
        }
        e
    }

    /// The indices of the generations held (oldest first).
    pub fn generations(&self) -> Vec<u64> {
        let mut v: Vec<u64> = self.slots.iter().map(|g| g.index).collect();
        v.sort_unstable();
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_sum_to_the_photon_count() {
        for (n, m) in [(1000u32, 3u32), (7, 7), (1 << 18, 5), (65, 64)] {
            let shares: Vec<u32> = (0..m as u64).map(|g| photons_of(g, n, m)).collect();
            assert_eq!(shares.iter().sum::<u32>(), n, "{n} over {m}");
            assert!(shares.iter().max().unwrap() - shares.iter().min().unwrap() <= 1);
            // A later generation in the same slot has the same share.
            assert_eq!(photons_of(m as u64 + 1, n, m), shares[1]);
        }
    }
}
