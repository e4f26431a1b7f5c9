//! The model `auto` picks by, fitted to the benchmark's measurements (measurements.json, the
//! schema of issue 21, written by scripts/bench_solvers.py; a provisional file from the solver
//! fixtures until then) and to the features of each measured scene (scene_features.json,
//! written from the measured scenes by the `scene_features_are_up_to_date` test with
//! VOLSCATTER_BLESS=1). Both are embedded with include_str! and parsed once.
//!
//! The model, per configuration (solver, quality, settings: one measured configuration):
//! - error: kernel regression in log space over the measured scenes that ran it,
//!   ln e(q) = sum_s w_s ln e_s / sum_s w_s with w_s = exp(-d(q, s)^2 / 2), where d is the
//!   distance of `distance` below; a measured scene at distance 0 (the query is that scene) is
//!   used alone, so that on measured scenes the prediction is the measurement;
//! - seconds: a weighted geometric mean of the measured solve seconds scaled by voxels^(1/3) (not
//!   lpm's: it solves on its own grid)
//!   (and, for lpm and photon-grid, by the scattering orders: `orders_scaling`), with weights from
//!   `time_distance` (light kinds and size: what sets the cost), plus the
//!   measured composite seconds scaled by pixels x voxels^(1/3) (the compositor marches every
//!   pixel through the grid, in steps of a voxel).
//!
//! The candidates are the configurations measured on the measured scene nearest the query: one
//! missing there was cancelled or skipped as too slow on it (measure.rs), and would otherwise
//! be predicted from the scenes where it was fast.
//!
//! Only CPU runs are used: every host has a CPU; a GPU backend only makes the pick faster.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use serde::Deserialize;
use serde_json::{Map, Value};

use super::features::Features;
use crate::error::{Error, Result};

/// The measurements and the measured scenes' features, as committed.
const MEASUREMENTS_JSON: &str = include_str!("measurements.json");
const FEATURES_JSON: &str = include_str!("scene_features.json");

/// One measured scene: its name, where it is (`scene`, relative to the repository root, or
/// `fixture`, a solver fixture of core/src/solvers/fixtures in the provisional file), and the
/// reference's own image noise.
#[derive(Clone, Debug, Deserialize)]
pub struct MeasuredScene {
    pub name: String,
    #[serde(default)]
    pub scene: Option<String>,
    #[serde(default)]
    pub fixture: Option<String>,
    #[serde(default)]
    pub reference_noise: Option<f64>,
    /// In the scene set's fixed held-out subset (bench/scenes/set.json): auto's acceptance fits
    /// without these scenes and picks for them.
    #[serde(default)]
    pub held_out: bool,
}

/// One solver run on one scene.
#[derive(Clone, Debug, Deserialize)]
pub struct Run {
    pub scene: String,
    pub solver: String,
    pub quality: String,
    #[serde(default)]
    pub settings: Map<String, Value>,
    #[serde(default = "cpu")]
    pub device: String,
    pub seconds: f64,
    #[serde(default)]
    pub solve_seconds: Option<f64>,
    #[serde(default)]
    pub composite_seconds: Option<f64>,
    /// The near-lamp pass's share of the composite (compositor/near_lamps.rs).
    #[serde(default)]
    pub near_lamp_seconds: Option<f64>,
    pub image_error: f64,
    #[serde(default)]
    pub grid_error: Option<f64>,
}

fn cpu() -> String {
    "cpu".into()
}

/// The measurements file (issue 21's schema; `cycles` rows are read but not used by the pick).
#[derive(Clone, Debug, Deserialize)]
pub struct Measurements {
    pub format: u32,
    #[serde(default)]
    pub written_by: String,
    #[serde(default)]
    pub machine: String,
    #[serde(default)]
    pub date: String,
    #[serde(default)]
    pub error: String,
    pub scenes: Vec<MeasuredScene>,
    pub runs: Vec<Run>,
    #[serde(default)]
    pub cycles: Vec<Value>,
}

impl Measurements {
    pub fn parse(text: &str) -> Result<Self> {
        let m: Measurements = serde_json::from_str(text).map_err(|e| Error::InvalidArgument(format!("auto: measurements: {e}")))?;
        if m.format != 1 {
            return Err(Error::InvalidArgument(format!("auto: measurements format {} (this build reads 1)", m.format)));
        }
        Ok(m)
    }
}

/// scene_features.json: the features of each measured scene, by name.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize)]
pub struct FeatureTable {
    pub format: u32,
    pub scenes: BTreeMap<String, Features>,
}

/// A configuration the pick can choose: a solver with the settings it was measured at.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    pub solver: String,
    pub quality: String,
    pub settings: Map<String, Value>,
}

/// One measurement of a configuration on a scene, in the model's terms.
#[derive(Clone, Debug)]
pub struct Observation {
    pub scene: usize,
    pub error: f64,
    pub seconds: f64,
    pub solve_seconds: f64,
    pub composite_seconds: f64,
    /// The near-lamp pass's share of `composite_seconds`.
    pub near_lamp_seconds: f64,
}

/// The fitted model: the measured scenes with their features, and per configuration its
/// observations.
#[derive(Clone, Debug)]
pub struct Model {
    pub scenes: Vec<(String, Features)>,
    pub configs: Vec<(Config, Vec<Observation>)>,
}

/// A prediction for one configuration on one scene.
#[derive(Clone, Copy, Debug)]
pub struct Prediction {
    pub error: f64,
    pub seconds: f64,
    /// Index (into `Model::scenes`) of the measured scene with the largest weight.
    pub nearest: usize,
}

/// Distance between two scenes' features, in units where 1 is "a different regime": a factor
/// of 2 in 1 + optical depth (mean or max), a factor of e in 1 - albedo (0.99 -> 0.97), 0.3 in
/// g, or one light class present in one scene and not the other. Image size and voxel count
/// are left out: they change the cost (scaled in `predict`), not which solver is accurate.
pub fn distance(a: &Features, b: &Features) -> f64 {
    let ln2 = std::f64::consts::LN_2;
    let tau = |x: f64| (1.0 + x.max(0.0)).ln() / ln2;
    let absorb = |al: f64| (1.0 - al.clamp(0.0, 1.0) + 1e-3).ln();
    let lights = a.lights.named().iter().zip(b.lights.named()).filter(|(x, y)| x.1 != y.1).count() as f64;
    let d2 = (tau(a.tau_mean) - tau(b.tau_mean)).powi(2)
        + (tau(a.tau_max) - tau(b.tau_max)).powi(2)
        + (absorb(a.albedo) - absorb(b.albedo)).powi(2)
        + ((a.g - b.g) / 0.3).powi(2)
        + lights;
    d2.sqrt()
}

/// Distance between two scenes for the time prediction: what sets a solver's cost is which
/// kinds of light it handles (dome ordinates, one sample per point or spot light, samples over
/// an area light's surface, emission VPLs) and the medium's size, far more than its albedo or g
/// (issue 36's scene set: a separate time kernel took leave-one-scene-out time predictions from
/// 22 to 24 of 29 within 2x). A light kind present in one scene and not the other counts 2, a
/// local light inside the medium in one and outside in the other 1 (the kind sets the cost more
/// than where it sits: an area light outside took the time of the disc inside, not of the point
/// lights outside), a factor of e in voxels 1, the optical depth half as much as in `distance`.
pub fn time_distance(a: &Features, b: &Features) -> f64 {
    let ln2 = std::f64::consts::LN_2;
    let tau = |x: f64| (1.0 + x.max(0.0)).ln() / ln2;
    let kinds = a.lights.kinds().iter().zip(b.lights.kinds()).filter(|(x, y)| x.1 != y.1).count() as f64;
    let sides = (a.lights.local_inside != b.lights.local_inside) as u8 + (a.lights.local_outside != b.lights.local_outside) as u8;
    let d2 = 4.0 * (kinds + 0.25 * sides as f64) + (a.voxels.max(1.0) / b.voxels.max(1.0)).ln().powi(2) + 0.25 * (tau(a.tau_mean) - tau(b.tau_mean)).powi(2);
    d2.sqrt()
}

/// How a configuration's solve time grows with the scattering orders its medium needs
/// (`Features::scattering_orders`, at lpm's `epsilon` and `max_orders` where the configuration
/// has them): the solve time is scaled by the orders' ratio to this power. lpm's work is
/// cells x directions x orders (solvers/lpm/cost.rs) and photon-grid's photons scatter about as
/// many times before they leave, but later orders light fewer cells: on the scene set both
/// solvers' times grow as about the orders' square root (lpm's propagation 1.3 s at 9 orders,
/// 4 s at 61). Leave-one-scene-out, that took time predictions from 25 to 26 of 29 within 2x;
/// network's, pop's and vpl's times did not follow the orders, so theirs are not scaled.
/// Beyond the most orders measured, photon-grid's time grows with the orders themselves (every
/// order traces every photon on); lpm's does not: past twice a usual solve's orders its late
/// orders run over a sixth of the directions (solvers/lpm/coarse.rs).
const ORDERS_EXPONENT: f64 = 0.5;

/// (epsilon, max_orders, exponent, linear beyond the measured orders) of `config`'s orders
/// scaling; None: its time is not scaled.
fn orders_scaling(config: &Config) -> Option<(f64, f64, f64, bool)> {
    matches!(config.solver.as_str(), "lpm" | "photon-grid").then(|| {
        let get = |k: &str, default: f64| config.settings.get(k).and_then(|v| v.as_f64()).unwrap_or(default);
        (get("epsilon", 1e-3), get("max_orders", 200.0), ORDERS_EXPONENT, config.solver == "photon-grid")
    })
}

impl Model {
    /// The model of the committed files, parsed once (an error in them is a build defect that
    /// the tests catch; it is reported, not panicked on).
    pub fn embedded() -> Result<&'static Model> {
        static MODEL: OnceLock<std::result::Result<Model, String>> = OnceLock::new();
        MODEL
            .get_or_init(|| Model::from_json(MEASUREMENTS_JSON, FEATURES_JSON).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|e| Error::InvalidArgument(e.clone()))
    }

    pub fn from_json(measurements: &str, features: &str) -> Result<Model> {
        let m = Measurements::parse(measurements)?;
        let table: FeatureTable =
            serde_json::from_str(features).map_err(|e| Error::InvalidArgument(format!("auto: scene features: {e}")))?;
        Model::fit(&m, &table)
    }

    /// The model of `m`'s CPU runs on the scenes that `table` has features of (a scene without
    /// features is an error: the feature table is regenerated with the measurements).
    pub fn fit(m: &Measurements, table: &FeatureTable) -> Result<Model> {
        let mut scenes = Vec::new();
        for s in &m.scenes {
            let f = table.scenes.get(&s.name).ok_or_else(|| {
                Error::InvalidArgument(format!("auto: measured scene `{}` has no features in scene_features.json (regenerate it)", s.name))
            })?;
            scenes.push((s.name.clone(), f.clone()));
        }
        let mut configs: Vec<(Config, Vec<Observation>)> = Vec::new();
        for r in m.runs.iter().filter(|r| r.device == "cpu" && r.solver != super::NAME) {
            let Some(scene) = scenes.iter().position(|(n, _)| *n == r.scene) else { continue };
            if !(r.image_error.is_finite() && r.image_error > 0.0 && r.seconds.is_finite() && r.seconds > 0.0) {
                continue;
            }
            let config = Config { solver: r.solver.clone(), quality: r.quality.clone(), settings: r.settings.clone() };
            let composite = r.composite_seconds.unwrap_or(0.0).max(0.0);
            let obs = Observation {
                scene,
                error: r.image_error,
                seconds: r.seconds,
                solve_seconds: r.solve_seconds.unwrap_or(r.seconds - composite).max(1e-6),
                composite_seconds: composite,
                near_lamp_seconds: r.near_lamp_seconds.unwrap_or(0.0).clamp(0.0, composite),
            };
            match configs.iter_mut().find(|(c, _)| *c == config) {
                Some((_, v)) => v.push(obs),
                None => configs.push((config, vec![obs])),
            }
        }
        Ok(Model { scenes, configs })
    }

    /// The same model without scene `name`'s runs (leave-one-scene-out).
    pub fn without(&self, name: &str) -> Model {
        let Some(gone) = self.scenes.iter().position(|(n, _)| n == name) else { return self.clone() };
        let scenes = self.scenes.iter().filter(|(n, _)| n != name).cloned().collect();
        let configs = self
            .configs
            .iter()
            .map(|(c, obs)| {
                let kept = obs
                    .iter()
                    .filter(|o| o.scene != gone)
                    .map(|o| Observation { scene: if o.scene > gone { o.scene - 1 } else { o.scene }, ..o.clone() })
                    .collect();
                (c.clone(), kept)
            })
            .filter(|(_, obs): &(Config, Vec<Observation>)| !obs.is_empty())
            .collect();
        Model { scenes, configs }
    }

    /// Index (into `scenes`) of the measured scene nearest to features `f`.
    pub fn nearest_scene(&self, f: &Features) -> Option<usize> {
        (0..self.scenes.len()).min_by(|&a, &b| distance(f, &self.scenes[a].1).total_cmp(&distance(f, &self.scenes[b].1)))
    }

    /// Whether configuration `i` was measured on scene `s`.
    pub fn measured_on(&self, i: usize, s: usize) -> bool {
        self.configs.get(i).is_some_and(|(_, obs)| obs.iter().any(|o| o.scene == s))
    }

    /// Whether another configuration measured on scene `s` was both faster and more accurate
    /// there than configuration `i` (at least as good in both, better in one), among those
    /// `among` admits.
    pub fn dominated_on(&self, i: usize, s: usize, among: impl Fn(usize) -> bool) -> bool {
        let on = |j: usize| self.configs[j].1.iter().find(|o| o.scene == s).map(|o| (o.error, o.seconds));
        let Some((e, t)) = on(i) else { return false };
        (0..self.configs.len()).any(|j| j != i && among(j) && on(j).is_some_and(|(ej, tj)| ej <= e && tj <= t && (ej < e || tj < t)))
    }

    /// Whether configuration `i` is dominated (`dominated_on`) on the measured scenes nearest
    /// a scene of features `f`: on scenes holding more than half of the weight that `predict`
    /// gives its measurements (on a measured scene, on that scene alone). One neighbour is not
    /// enough: sub-second times vary 2-4x with the machine's load, and one lucky run of a draft
    /// on the nearest scene would strike a preview everywhere around it.
    pub fn dominated_near(&self, i: usize, f: &Features, among: impl Fn(usize) -> bool) -> bool {
        let Some((_, obs)) = self.configs.get(i) else { return false };
        let d: Vec<f64> = obs.iter().map(|o| distance(f, &self.scenes[o.scene].1)).collect();
        let exact = d.iter().any(|&x| x < 1e-9);
        let (mut dominated, mut total) = (0.0, 0.0);
        for (o, &x) in obs.iter().zip(&d) {
            let w = if exact { f64::from(x < 1e-9) } else { (-0.5 * x * x).exp() };
            total += w;
            if w > 0.0 && self.dominated_on(i, o.scene, &among) {
                dominated += w;
            }
        }
        total > 0.0 && dominated > 0.5 * total
    }

    /// Configuration `i`'s predicted error and seconds on a scene of features `f`.
    pub fn predict(&self, i: usize, f: &Features) -> Option<Prediction> {
        let obs = &self.configs.get(i)?.1;
        let d: Vec<f64> = obs.iter().map(|o| distance(f, &self.scenes[o.scene].1)).collect();
        let exact = d.iter().any(|&x| x < 1e-9);
        let w: Vec<f64> = d.iter().map(|&x| if exact { if x < 1e-9 { 1.0 } else { 0.0 } } else { (-0.5 * x * x).exp().max(1e-300) }).collect();
        let total: f64 = w.iter().sum();
        if obs.is_empty() || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let nearest = obs.iter().zip(&w).max_by(|a, b| a.1.total_cmp(b.1)).map(|(o, _)| o.scene).unwrap_or(0);
        if exact {
            // The query is a measured scene: its measurement, exactly (no ln/exp rounding, so
            // that a target equal to a measured error is met by that run).
            let o = obs.iter().zip(&d).find(|(_, &x)| x < 1e-9).map(|(o, _)| o)?;
            let f_s = &self.scenes[o.scene].1;
            let scale = (f.pixels / f_s.pixels.max(1.0)) * (f.voxels / f_s.voxels.max(1.0)).cbrt();
            return Some(Prediction { error: o.error, seconds: o.seconds + o.composite_seconds * (scale - 1.0), nearest });
        }
        let mean_ln = |w: &[f64], v: &dyn Fn(&Observation) -> f64| {
            obs.iter().zip(w).map(|(o, w)| w * v(o).max(1e-12).ln()).sum::<f64>() / w.iter().sum::<f64>()
        };
        let error = mean_ln(&w, &|o| o.error).exp();
        // Time from the scenes nearest in what sets the cost (`time_distance`); the solve
        // scaled by the cube root of the voxels (its marches cross the medium voxel by voxel).
        let wt: Vec<f64> = obs.iter().map(|o| (-0.5 * time_distance(f, &self.scenes[o.scene].1).powi(2)).exp().max(1e-300)).collect();
        let voxels = |o: &Observation| (f.voxels / self.scenes[o.scene].1.voxels.max(1.0)).cbrt();
        // lpm solves on its own grid (`grid_resolution` cells along the longest side), whatever
        // the medium's voxels: its solve is not scaled by them.
        let solve_voxels = |o: &Observation| if self.configs[i].0.solver == "lpm" { 1.0 } else { voxels(o) };
        let scaling = orders_scaling(&self.configs[i].0);
        let measured_most = scaling.map_or(1.0, |(eps, max, _, _)| obs.iter().map(|o| self.scenes[o.scene].1.scattering_orders(eps, max)).fold(1.0, f64::max));
        let orders = |o: &Observation| match scaling {
            Some((eps, max, k, linear_beyond)) => {
                let q = f.scattering_orders(eps, max);
                let beyond = if linear_beyond { (q / measured_most).max(1.0) } else { 1.0 };
                (q.min(measured_most) / self.scenes[o.scene].1.scattering_orders(eps, max)).powf(k) * beyond
            }
            None => 1.0,
        };
        let solve = mean_ln(&wt, &|o| o.solve_seconds * solve_voxels(o) * orders(o)).exp();
        // The composite's march scales with the pixels and the voxels it crosses; its near-lamp
        // pass with the lamps (each a march of its own over the pixels near it), from the
        // per-lamp cost of the nearest runs that had lamps.
        let composite = obs
            .iter()
            .zip(&wt)
            .map(|(o, w)| {
                let s = &self.scenes[o.scene].1;
                w * (o.composite_seconds - o.near_lamp_seconds) * (f.pixels / s.pixels.max(1.0)) * voxels(o)
            })
            .sum::<f64>()
            / wt.iter().sum::<f64>();
        let (per_lamp, lit) = obs.iter().zip(&wt).filter(|(o, _)| self.scenes[o.scene].1.lamps > 0.0).fold((0.0, 0.0), |(sum, total), (o, w)| {
            let s = &self.scenes[o.scene].1;
            (sum + w * o.near_lamp_seconds / s.lamps * (f.pixels / s.pixels.max(1.0)), total + w)
        });
        let near_lamps = if lit > 0.0 { f.lamps * per_lamp / lit } else { 0.0 };
        let composite = composite + near_lamps;
        Some(Prediction { error, seconds: solve + composite, nearest })
    }
}
