//! Photon tracing (Sec. 4.1.1, App. A): photons from the shared light sampling, Woodcock
//! (spectral) tracking against the majorant grid with a deposit into the cache at every
//! tentative collision, HG scattering, the transmittance cutoff and the similarity switch.
//!
//! A deposit at a tentative collision of a photon of power P and weight beta is
//! P beta rho(x) / majorant: tentative collisions are a Poisson process of rate `majorant`
//! along the ray, so the deposits sum in expectation to P times the integral of beta rho along
//! the track, and with spectral tracking E[beta 1{alive at t}] is the transmittance per
//! channel: an unbiased estimate of the integral of rho * fluence (cache.rs). Unlike the
//! paper's photon marching, no second stepping along the ray is needed (its Fig. 5).
//!
//! Spectral tracking is Tracking's (medium/tracking.rs: real-collision probability from the
//! history-aware max heuristic), through `sample_free_flight_visiting`, which shows the
//! deposits every tentative collision.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::cache::Cache;
use super::fixed::FixedTallies;
use super::settings::PhotonGridSettings;
use crate::medium::{ray_box, FreeFlight, MajorantGrid, Medium, Tracking};
use crate::phase::HenyeyGreenstein;
use crate::rng::Rng;
use crate::sampling::uniform_sphere;
use crate::translate::LightSampler;

/// Batches the photons are split into: fixed (not the thread count), so the result depends on
/// the seed only.
pub const BATCHES: u32 = 16;

/// Where the emitted power went (W, RGB, already divided by the photon count).
#[derive(Clone, Copy, Debug, Default)]
pub struct EnergyReport {
    /// Photons traced.
    pub photons: u64,
    pub emitted: DVec3,
    /// Left the medium's box.
    pub escaped: DVec3,
    /// Removed at real collisions by albedo < 1.
    pub absorbed: DVec3,
    /// Stopped by the cutoff with this weight left.
    pub cut: DVec3,
    /// Scattering events, total, and how many photons took the similarity switch.
    pub scatterings: u64,
    pub switched: u64,
}

impl EnergyReport {
    pub fn add(&mut self, o: &EnergyReport) {
        self.photons += o.photons;
        self.emitted += o.emitted;
        self.escaped += o.escaped;
        self.absorbed += o.absorbed;
        self.cut += o.cut;
        self.scatterings += o.scatterings;
        self.switched += o.switched;
    }
}

/// One medium as tracked: the real one, or its reduced twin after the similarity switch.
struct Phase<'a> {
    medium: &'a Medium,
    majorant: &'a MajorantGrid,
    /// HG anisotropy of scattering (0 in the reduced medium).
    g: f32,
}

/// The reduced medium of the similarity switch: sigma_s' = f sigma_s, sigma_a unchanged, so
/// sigma_t' = sigma_t (albedo f + 1 - albedo) and albedo' = albedo f / (albedo f + 1 - albedo),
/// per channel; isotropic. (A copy of the density: fine for the grids this first landing
/// targets; a scaled view would avoid it.)
pub fn reduced_medium(medium: &Medium, f: f32) -> Medium {
    let a = medium.albedo;
    let t = a * f + (Vec3::ONE - a);
    let mut m = medium.clone();
    m.density_scale = medium.density_scale * t;
    m.albedo = (a * f) / t.max(Vec3::splat(1e-12));
    m.g = 0.0;
    m.emission = None;
    m
}

pub struct Tracer<'a> {
    pub medium: &'a Medium,
    pub majorant: &'a MajorantGrid,
    pub reduced: Option<(&'a Medium, &'a MajorantGrid)>,
    pub settings: &'a PhotonGridSettings,
    /// Deposit before the first real collision too (single scattering from photons).
    pub deposit_unscattered: bool,
    /// Deposits of photons scattered this often or more go to the second lobe.
    pub split_order: u32,
    /// Read every `CANCEL_STRIDE` photons: once cancelled the batches stop early and the
    /// caller discards their tallies.
    pub progress: &'a dyn crate::stages::Progress,
    /// `Angular::Camera` (settings.rs): deposits weighted by the exact phase function towards
    /// this camera position, with no direction, so the cache holds S itself per cell (no lobe
    /// model, only the spatial binning). None: the lobes.
    pub view_from: Option<Vec3>,
}

/// Photons between two reads of the cancel flag: a photon is microseconds (longer in dense
/// media), so a worker sees a cancel within milliseconds.
const CANCEL_STRIDE: u64 = 256;

impl Tracer<'_> {
    /// Traces generation `generation` (`count` photons, each of power 1 / `total` of its
    /// light's: a generation is `count / total` of a full solve) and returns its tallies per
    /// lobe in fixed point and its energy report. Its batches draw from random streams of
    /// their own, `generation` x BATCHES + batch + 1, so generation 0 is the one-off solve's
    /// photons when there is one generation, and every generation is reproducible alone (the
    /// ring's exactness, ring.rs).
    pub fn run_generation(&self, sampler: &LightSampler, empty: &Cache, generation: u64, count: u32, total: u32) -> ([FixedTallies; 2], EnergyReport) {
        let results: Vec<([Cache; 2], EnergyReport)> = (0..BATCHES)
            .into_par_iter()
            // A batch started after a cancel allocates nothing (two caches of the whole grid).
            .filter(|_| !self.progress.cancelled())
            .map(|b| {
                let mut cache = [empty.empty_like(), empty.empty_like()];
                let mut report = EnergyReport::default();
                let mut rng = Rng::new(self.settings.seed, generation * BATCHES as u64 + b as u64 + 1);
                let (lo, hi) = (count as u64 * b as u64 / BATCHES as u64, count as u64 * (b as u64 + 1) / BATCHES as u64);
                for p in lo..hi {
                    if p % CANCEL_STRIDE == 0 && self.progress.cancelled() {
                        break;
                    }
                    if let Some(ray) = sampler.sample_rng(&mut rng) {
                        self.photon(ray.origin, ray.direction, ray.power / total as f32, &mut rng, &mut cache, &mut report);
                    }
                }
                (cache, report)
            })
            .collect();
        let mut report = EnergyReport::default();
        for (_, r) in &results {
            report.add(r);
        }
        // Cut short: the caller discards the tallies, so none are summed.
        if self.progress.cancelled() {
            return ([FixedTallies::zeros(0), FixedTallies::zeros(0)], report);
        }
        let lobe = |l: usize| FixedTallies::sum_of_cancellable(&results.iter().map(|(c, _)| &c[l]).collect::<Vec<_>>(), self.progress);
        ([lobe(0), lobe(1)], report)
    }

    /// A deposit's flux and direction as stored: as traced, or under `view_from` the flux
    /// times 4 pi p_HG towards the camera and no direction (the reconstruction's lobe is then
    /// isotropic, 1 / 4 pi, and gives back sigma_s times the cell's mean of p_HG L).
    #[inline]
    fn view_weighted(&self, p: Vec3, d: Vec3, f: Vec3) -> (Vec3, Vec3) {
        if let Some(camera) = self.view_from {
            let k = 4.0 * std::f32::consts::PI * crate::phase::hg((camera - p).normalize_or_zero().dot(d), self.medium.g);
            return (f * k, Vec3::ZERO);
        }
        (f, d)
    }

    /// One photon of power `power` from `x` along `d` to its end.
    fn photon(&self, mut x: Vec3, mut d: Vec3, power: Vec3, rng: &mut Rng, caches: &mut [Cache; 2], report: &mut EnergyReport) {
        report.photons += 1;
        report.emitted += power.as_dvec3();
        let mut beta = Vec3::ONE;
        let mut order = 0u32;
        let switch_at = self.reduced.and(self.settings.switch_order(self.medium.g));
        let full = Phase { medium: self.medium, majorant: self.majorant, g: self.medium.g };
        let mut phase = &full;
        let reduced = self.reduced.map(|(medium, majorant)| Phase { medium, majorant, g: 0.0 });
        let (lo, hi) = self.medium.world_bounds();
        // Nothing to track outside the medium's box (light rays start on the bounding sphere,
        // outside it); no box ahead: escaped.
        while let Some((t0, t1)) = ray_box(x, d, lo, hi) {
            if t1 <= t0.max(0.0) {
                break;
            }
            let deposit = order > 0 || self.deposit_unscattered;
            let cache = &mut caches[(order >= self.split_order) as usize];
            let (hit, w) = track(phase, x, d, beta, rng, |p, w, rho_over_m| {
                if deposit {
                    let f = power * w * rho_over_m;
                    let (flux, dir) = self.view_weighted(p, d, f);
                    cache.deposit(p, flux, f.element_sum() / 3.0, dir, order);
                }
            });
            match hit {
                None => {
                    beta = w;
                    break;
                }
                Some(t) => {
                    x += d * t;
                    // Real collision: scatter with the albedo, the rest is absorbed.
                    let rho = phase.medium.density_world(x);
                    let albedo = if rho > 0.0 { phase.medium.albedo } else { Vec3::ONE };
                    report.absorbed += (power * w * (Vec3::ONE - albedo)).as_dvec3();
                    beta = w * albedo;
                    order += 1;
                    report.scatterings += 1;
                    if beta.max_element() < self.settings.cutoff || beta.max_element() <= 0.0 {
                        report.cut += (power * beta).as_dvec3();
                        return;
                    }
                    if let (Some(s), Some(r)) = (switch_at, reduced.as_ref()) {
                        if order == s {
                            phase = r;
                            report.switched += 1;
                        }
                    }
                    d = if phase.g == 0.0 { uniform_sphere(rng.pair()) } else { HenyeyGreenstein::new(phase.g).sample(d, rng.pair()) };
                }
            }
        }
        report.escaped += (power * beta).as_dvec3();
    }
}

/// Woodcock / spectral tracking (medium::Tracking) from `x` along `d` with throughput `beta`,
/// calling `deposit(point, weight before the decision, rho / majorant)` at every tentative
/// collision in the medium. Returns the distance of the real collision (None: escaped) and the
/// weight after tracking (spectral tracking reweights at null collisions too; grey media keep
/// it).
fn track(phase: &Phase, x: Vec3, d: Vec3, beta: Vec3, rng: &mut Rng, mut deposit: impl FnMut(Vec3, Vec3, f32)) -> (Option<f32>, Vec3) {
    let inv_scale = 1.0 / phase.medium.density_scale.max_element().max(1e-30);
    let tracking = Tracking::new(phase.medium, phase.majorant);
    let flight = tracking.sample_free_flight_visiting(x, d, f32::INFINITY, beta, rng, |t, w, sigma_t, m| {
        // rho from sigma_t = density_scale * rho (its largest channel, the same rho).
        let rho = sigma_t.max_element() * inv_scale;
        if rho > 0.0 {
            deposit(x + d * t, w, rho / m);
        }
    });
    match flight {
        FreeFlight::Scattered { t, weight } => (Some(t), weight),
        FreeFlight::Escaped { weight } => (None, weight),
    }
}
