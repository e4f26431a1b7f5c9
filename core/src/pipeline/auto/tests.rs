//! `auto` against its measurements (measurements.json): on every measured scene, for every
//! target error some measured run reaches and for every budget some run fits, the pick's
//! MEASURED error and cost are close to the best measured choice; leave-one-scene-out is
//! reported; unmeasured light types fall back to the stated default; bad settings are errors.

use crate::solvers::SolveCtx;
use crate::solvers::registry;
use serde_json::{json, Map, Value};

use super::model::{Measurements, Model, Run};
use super::pick::{pick, FALLBACK};
use super::*;
use crate::pipeline::{Devices, Session};
use crate::solvers::testing::fixture_scene;
use crate::stages::NoProgress;

/// The pick's measured error may exceed the target by this factor: the model predicts the
/// error from measurements that are themselves noisy (the reference's own noise, and the
/// solvers' Monte Carlo noise between runs).
const ERROR_MARGIN: f64 = 1.25;
/// The pick's measured seconds may exceed the cheapest measured configuration that meets the
/// target by this factor: timings on the shared machine vary by tens of percent run to run.
const COST_FACTOR: f64 = 2.0;

fn measurements() -> Measurements {
    Measurements::parse(include_str!("measurements.json")).unwrap()
}

fn model() -> &'static Model {
    Model::embedded().unwrap()
}

/// The measured CPU run of the configuration `c` on `scene`.
fn run_of<'a>(m: &'a Measurements, scene: &str, c: &Choice) -> Option<&'a Run> {
    m.runs.iter().find(|r| r.scene == scene && r.device == "cpu" && r.solver == c.solver && r.quality == c.quality && r.settings == c.settings)
}

fn cpu_runs<'a>(m: &'a Measurements, scene: &'a str) -> impl Iterator<Item = &'a Run> + 'a {
    m.runs.iter().filter(move |r| r.scene == scene && r.device == "cpu" && r.solver != NAME)
}

fn features_of(model: &Model, scene: &str) -> Features {
    model.scenes.iter().find(|(n, _)| n == scene).map(|(_, f)| f.clone()).unwrap()
}

/// (target, the pick's measured (error, seconds), the cheapest measured seconds meeting the
/// target, "solver quality" of the pick).
type TargetRow = (f64, Option<(f64, f64)>, f64, String);

/// For each target error some run on `scene` reached: the pick of `model` there.
fn target_rows(m: &Measurements, model: &Model, scene: &str, f: &Features) -> Vec<TargetRow> {
    let mut targets: Vec<f64> = cpu_runs(m, scene).map(|r| r.image_error).collect();
    targets.sort_by(f64::total_cmp);
    targets.dedup();
    targets
        .into_iter()
        .map(|t| {
            let cheapest = cpu_runs(m, scene).filter(|r| r.image_error <= t).map(|r| r.seconds).fold(f64::INFINITY, f64::min);
            let c = pick(model, f, t, 0.0, registry::preset_settings);
            let got = run_of(m, scene, &c).map(|r| (r.image_error, r.seconds));
            (t, got, cheapest, format!("{} {}", c.solver, c.quality))
        })
        .collect()
}

#[test]
fn picks_reach_every_reachable_target_at_near_the_lowest_measured_cost() {
    let (m, model) = (measurements(), model());
    assert!(!model.scenes.is_empty() && !model.configs.is_empty(), "no measurements");
    let mut failures = Vec::new();
    let mut checked = 0;
    for (scene, f) in &model.scenes {
        for (t, got, cheapest, what) in target_rows(&m, model, scene, f) {
            checked += 1;
            match got {
                Some((e, s)) if e <= t * ERROR_MARGIN && s <= cheapest * COST_FACTOR => {}
                Some((e, s)) => failures.push(format!("{scene} target {t:.4}: {what} measured {e:.4} in {s:.2} s (cheapest meeting it {cheapest:.2} s)")),
                None => failures.push(format!("{scene} target {t:.4}: {what} was not measured there")),
            }
        }
    }
    eprintln!("{checked} (scene, target) pairs, {} outside the margins", failures.len());
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn picks_within_a_budget_are_the_most_accurate_measured_within_it() {
    let (m, model) = (measurements(), model());
    let mut failures = Vec::new();
    for (scene, f) in &model.scenes {
        let mut budgets: Vec<f64> = cpu_runs(&m, scene).map(|r| r.seconds).collect();
        budgets.sort_by(f64::total_cmp);
        for b in budgets {
            let best = cpu_runs(&m, scene).filter(|r| r.seconds <= b).map(|r| r.image_error).fold(f64::INFINITY, f64::min);
            let c = pick(model, f, 0.1, b, registry::preset_settings);
            match run_of(&m, scene, &c) {
                Some(r) if r.seconds <= b * COST_FACTOR && r.image_error <= best * ERROR_MARGIN => {}
                Some(r) => failures.push(format!(
                    "{scene} budget {b:.2} s: {} {} measured {:.4} in {:.2} s (best within the budget {best:.4})",
                    c.solver, c.quality, r.image_error, r.seconds
                )),
                None => failures.push(format!("{scene} budget {b:.2} s: {} {} was not measured there", c.solver, c.quality)),
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The issue-36 acceptance of one pick on a scene it was not fitted to: its measured error within
/// this factor of the best error measured there at no more than its measured time...
const LOSO_ERROR_FACTOR: f64 = 1.5;
/// ...and its measured time within this factor of its predicted time (either way), or within
/// LOSO_TIME_SLACK seconds of it: runs of 0.02-0.3 s vary 2-4x between runs on the shared 2-core
/// machine the measurements were taken on (load averages of 10 and more), so below a quarter of
/// a second a ratio says nothing about the model.
const LOSO_TIME_FACTOR: f64 = 2.0;
const LOSO_TIME_SLACK: f64 = 0.25;
/// The share of left-out scenes whose pick's error must pass (the 90%)...
const LOSO_PASS_SHARE: f64 = 0.9;
/// ...and the share that must pass error and time together: the 90% too
/// (BENCHMARKS.md `auto-acceptance` names the misses).
const LOSO_BOTH_FLOOR: f64 = 0.9;

/// One left-out scene's pick at the default target by `model` (fitted without it): (error passed,
/// error and time passed, a table row "| scene | pick | predicted | measured | best at its time | ... |").
fn held_out_pick(m: &Measurements, model: &Model, scene: &str, f: &Features) -> (bool, bool, String) {
    let c = pick(model, f, AutoSettings::default().target_error, 0.0, registry::preset_settings);
    let what = format!("{} {}", c.solver, c.quality);
    let pred = match (c.predicted_error, c.predicted_seconds) {
        (Some(e), Some(s)) => format!("{e:.3} in {s:.2} s"),
        _ => "fallback".into(),
    };
    let Some(r) = run_of(m, scene, &c) else {
        return (false, false, format!("| {scene} | {what} | {pred} | not measured there (capped or skipped) | - | fail |"));
    };
    let best = cpu_runs(m, scene).filter(|x| x.seconds <= r.seconds).map(|x| x.image_error).fold(f64::INFINITY, f64::min);
    let time_ratio = c.predicted_seconds.map_or(f64::INFINITY, |p| r.seconds / p);
    let ok_error = r.image_error <= LOSO_ERROR_FACTOR * best;
    let ok_time = (1.0 / LOSO_TIME_FACTOR..=LOSO_TIME_FACTOR).contains(&time_ratio)
        || c.predicted_seconds.is_some_and(|p| (r.seconds - p).abs() <= LOSO_TIME_SLACK);
    let verdict = match (ok_error, ok_time) {
        (true, true) => "pass".to_string(),
        (false, true) => format!("fail: error {:.1}x the best", r.image_error / best),
        (true, false) => format!("fail: time {time_ratio:.2}x the prediction"),
        (false, false) => format!("fail: error {:.1}x the best, time {time_ratio:.2}x", r.image_error / best),
    };
    (ok_error, ok_error && ok_time, format!("| {scene} | {what} | {pred} | {:.3} in {:.2} s | {best:.3} | {verdict} |", r.image_error, r.seconds))
}

/// Leave-one-scene-out acceptance (issue 36): fitted without each measured scene in turn, auto
/// at its default target picks for it; on at least 90% of the scenes the pick's measured error is
/// within 1.5x of the best error measured there at no more than its time, and its measured time
/// within 2x of its prediction (or a quarter of a second: LOSO_TIME_SLACK). The table printed (rows starting "| ") is BENCHMARKS.md's
/// `auto-acceptance` (scripts/bench_solvers.py --auto-acceptance). The fixed held-out subset
/// (fitted without all of it at once) is printed too.
#[test]
fn leave_one_scene_out() {
    let (m, full) = (measurements(), model());
    println!("| left-out scene | pick | predicted | measured | best error at its time | |\n|---|---|---|---|---:|---|");
    let (mut passed, mut error_passed, mut within_target) = (0, 0, 0);
    for (scene, f) in &full.scenes {
        let model = full.without(scene);
        let (ok_error, ok, row) = held_out_pick(&m, &model, scene, f);
        passed += ok as usize;
        error_passed += ok_error as usize;
        let c = pick(&model, f, AutoSettings::default().target_error, 0.0, registry::preset_settings);
        within_target += run_of(&m, scene, &c).is_some_and(|r| r.image_error <= AutoSettings::default().target_error) as usize;
        println!("{row}");
    }
    let n = full.scenes.len();
    let pct = |k: usize| 100.0 * k as f64 / n as f64;
    println!(
        "\nLeave-one-scene-out: {passed} of {n} picks pass both ({:.1}%), {error_passed} of {n} the error part ({:.1}%); \
         {within_target} of {n} picks measured within the target error itself ({:.1}%).",
        pct(passed),
        pct(error_passed),
        pct(within_target)
    );
    let held: Vec<&str> = m.scenes.iter().filter(|s| s.held_out).map(|s| s.name.as_str()).collect();
    let mut fitted = full.clone();
    for s in &held {
        fitted = fitted.without(s);
    }
    let held_passed = held.iter().filter(|s| held_out_pick(&m, &fitted, s, &features_of(full, s)).1).count();
    println!("Fixed held-out subset ({}), fitted without all of it: {held_passed} of {} pass both.\n", held.join(", "), held.len());
    assert!(n > 0 && error_passed as f64 >= LOSO_PASS_SHARE * n as f64, "{error_passed} of {n} left-out picks pass the error part (need {LOSO_PASS_SHARE})");
    assert!(passed as f64 >= LOSO_BOTH_FLOOR * n as f64, "{passed} of {n} left-out picks pass error and time (floor {LOSO_BOTH_FLOOR})");
}

/// A light type that no measured scene has: the stated default runs, and says why.
#[test]
fn unmeasured_light_types_fall_back_to_the_default_with_the_reason() {
    let full = model();
    // The measurements without every scene that has a local light outside the medium.
    let mut model = full.clone();
    for (name, s) in &full.scenes {
        if s.lights.local_outside {
            model = model.without(name);
        }
    }
    let model = &model;
    let mut f = model.scenes[0].1.clone();
    f.lights.local_outside = true;
    let c = pick(model, &f, 0.1, 0.0, registry::preset_settings);
    assert!(c.fallback && (c.solver.as_str(), c.quality.as_str()) == FALLBACK, "{c:?}");
    assert!(c.why.contains("has a local light outside the medium") && !c.why.contains("outside light") && c.predicted_error.is_none(), "{}", c.why);
    // Settings of the fallback are its registry preset, which builds.
    crate::solvers::registry::build(&c.solver, &c.settings).unwrap();
    // No measurements at all: the same default.
    let empty = Model { scenes: vec![], configs: vec![] };
    let c = pick(&empty, &features_of(model, &model.scenes[0].0), 0.1, 0.0, registry::preset_settings);
    assert!(c.fallback && c.why.contains("no measurements"), "{c:?}");
}

#[test]
fn bad_settings_are_clear_errors() {
    let bad = |k: &str, v: Value| {
        let mut m = Map::new();
        m.insert(k.into(), v);
        m
    };
    for (k, v) in [("target_error", json!(-0.1)), ("target_error", json!(0.0)), ("time_budget", json!(-1.0)), ("target_error", Value::from(f64::NAN))] {
        let s = bad(k, v.clone());
        let Err(e) = validate(&s) else { panic!("{k} = {v} accepted") };
        assert!(matches!(&e, Error::Scene { field, .. } if field == &format!("solver.{k}")), "{k} = {v}: {e}");
        assert!(choose(&fixture_scene("cube_g0"), &s, registry::preset_settings).is_err(), "{k} = {v}: choose accepted it");
    }
    assert!(validate(&bad("target", json!(0.1))).is_err(), "unknown key accepted");
}

/// `auto` runs exactly the solver and settings it says it picked, alone and in a session.
#[test]
fn runs_what_it_says_it_picked() {
    let sc = fixture_scene("cube_g0");
    let settings = json!({"target_error": 0.3}).as_object().unwrap().clone();
    let solved = crate::pipeline::solve(&sc, NAME, &settings, Devices::cpu(), &NoProgress).unwrap();
    let (out, c) = (solved.output, solved.choice.expect("auto gave no choice"));
    assert!(!c.fallback && c.predicted_error.is_some_and(|e| e <= 0.3), "{c:?}");
    let names_a_scene = model().scenes.iter().any(|(name, _)| c.why.contains(name.as_str()));
    assert!(c.why.contains("optical depth") && names_a_scene, "the sentence names no feature or measured scene: {}", c.why);
    let direct = crate::solvers::registry::build(&c.solver, &c.settings).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    assert_eq!(out.scattering.dims, direct.scattering.dims);
    // Deterministic solvers (fixed seeds): the same grid, to rounding of parallel sums.
    let diff = crate::image::relative_rmse(&out.scattering.data, &direct.scattering.data);
    assert!(diff < 1e-5, "auto's grid differs from {} {}'s by {diff}", c.solver, c.quality);
    let mut session = Session::new(NAME, &settings, Devices::cpu()).unwrap();
    for _ in 0..2 {
        let o = session.solve(&sc, &NoProgress).unwrap();
        assert_eq!(o.choice.as_ref().map(|c| &c.solver), Some(&c.solver));
    }
}

/// The default target is one the measured solvers reach on every measured scene whose reference
/// is converged enough to tell (its own noise under half the target: fig10_g08's fixture has
/// 0.31 of noise, so no error against it can be below about that), so that the hosts' default
/// never asks for the impossible. An error is judged as issue 36 states its aim, with the
/// reference's own noise taken out: sqrt(e^2 - noise^2).
/// Measured scenes no solver reaches the default (0.10) on: none since 2026-11-29.
/// s05_cloud_sun left the list when lpm's table kept the residual lobe's mean cosine (lpm
/// preview 0.252 -> 0.071), s23_sphere_dense when lpm's grid took two points a voxel (0.126 ->
/// 0.0996, 0.089 without its reference's noise of 0.045), s12_spot_inside when the composite
/// made a lamp's single scattering exact near it (photon-grid preview 0.375 -> 0.075, lpm final
/// 0.176 -> 0.086; compositor/near_lamps.rs).
const UNREACHED: &[&str] = &[];

#[test]
fn default_target_is_reached_on_every_measured_scene() {
    let (m, model) = (measurements(), model());
    let t = AutoSettings::default().target_error;
    for (scene, _) in &model.scenes {
        let noise = m.scenes.iter().find(|s| &s.name == scene).and_then(|s| s.reference_noise).unwrap_or(0.0);
        let best = cpu_runs(&m, scene).map(|r| r.image_error).fold(f64::INFINITY, f64::min);
        let best = (best * best - noise * noise).max(0.0).sqrt();
        if UNREACHED.contains(&scene.as_str()) {
            // Listed so that the day a solver reaches it, this fails and the list shrinks.
            assert!(best > t, "{scene} is listed as unreached but {best} <= {t}: remove it from UNREACHED");
        } else if noise < 0.5 * t {
            assert!(best <= t, "{scene}: no measured run reaches the default target {t} (best {best})");
        } else {
            eprintln!("{scene}: reference noise {noise:.3}, best run {best:.3}: not a test of the default");
        }
    }
}

/// Issue 40's dense white furnace (scripts/bench_cost_guard.py: a 16^3 plume at density scale 40,
/// albedo 1, under a white dome): no measured scene is that thick and white, and only the
/// scattering orders (the cap of 200, where the set's scenes need 7 to 61) tell the model so.
/// lpm preview's predicted time there and at a tenth of the density is within 2x of what it
/// measured after the scene set's measurements of lpm (5.9 s and 1.4 s, 2026-11-28, load
/// average 2; its late orders over fewer directions, solvers/lpm/coarse.rs), and larger at the
/// full density.
#[test]
fn lpm_time_follows_the_scattering_orders_of_a_dense_white_furnace() {
    let furnace = |density: f64| {
        let text = json!({"format": 1,
            "medium": {"procedural": "plume", "dims": [16], "density_scale": density, "albedo": 1.0},
            "lights": [{"type": "dome", "color": [1, 1, 1]}],
            "camera": {"position": [0, -4.5, 0.4], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 40, "width": 128, "height": 128}});
        crate::scene::Scene::from_json_str(&text.to_string(), std::path::Path::new(".")).unwrap()
    };
    let model = model();
    let lpm_preview = model.configs.iter().position(|(c, _)| c.solver == "lpm" && c.quality == "preview").expect("lpm preview measured");
    let (dense_scene, thin) = (furnace(40.0), Features::of(&furnace(4.0)));
    let dense = Features::of(&dense_scene);
    assert_eq!(dense.scattering_orders(1e-3, 200.0), 200.0, "{dense:?}");
    let seconds = |f: &Features| model.predict(lpm_preview, f).unwrap().seconds;
    let (t_dense, t_thin) = (seconds(&dense), seconds(&thin));
    eprintln!("lpm preview predicted {t_dense:.1} s on the dense white furnace, {t_thin:.1} s at a tenth of its density");
    let c = choose(&dense_scene, &Map::new(), registry::preset_settings).unwrap();
    eprintln!("auto on the dense white furnace: {}", c.why);
    let within_2x = |t: f64, measured: f64| (measured / 2.0..=measured * 2.0).contains(&t);
    assert!(within_2x(t_dense, 5.9), "lpm preview predicted {t_dense:.1} s on the dense white furnace (measured 5.9 s)");
    assert!(within_2x(t_thin, 1.4) && t_thin < t_dense, "at a tenth of the density: {t_thin:.1} s (measured 1.4 s; dense: {t_dense:.1} s)");
}

/// A configuration beaten on the nearest measured scene alone stays a candidate when it was not
/// beaten on the other neighbours, which hold more of the weight (sub-second times there vary
/// 2-4x with load: one run must not strike a configuration everywhere around it); beaten on
/// most of the weight, it is struck. Three scenes at distances 0.5, 0.6 and 0.7 from the query
/// (g apart by 0.15, 0.18, 0.21: `distance`'s unit is 0.3 in g).
#[test]
fn a_configuration_beaten_on_one_neighbour_alone_stays_a_candidate() {
    use super::model::{Config, Observation};
    let scene = |g: f64| Features { tau_mean: 2.0, tau_max: 4.0, albedo: 0.9, g, lights: Default::default(), lamps: 0.0, voxels: 32768.0, pixels: 1200.0 };
    let config = |solver: &str| Config { solver: solver.into(), quality: "preview".into(), settings: Map::new() };
    let obs = |scene: usize, error: f64, seconds: f64| Observation { scene, error, seconds, solve_seconds: seconds, composite_seconds: 0.0, near_lamp_seconds: 0.0 };
    let scenes = vec![("near".to_string(), scene(0.15)), ("b".to_string(), scene(0.18)), ("c".to_string(), scene(0.21))];
    // `fast` beats `slow` (better and faster) on the nearest scene only, then on two of three.
    let model = |beaten_on: &[usize]| Model {
        scenes: scenes.clone(),
        configs: vec![
            (config("slow"), (0..3).map(|s| obs(s, 0.05, 0.3)).collect()),
            (config("fast"), (0..3).map(|s| if beaten_on.contains(&s) { obs(s, 0.04, 0.1) } else { obs(s, 0.2, 0.1) }).collect()),
        ],
    };
    let query = scene(0.0);
    assert!(!model(&[0]).dominated_near(0, &query, |_| true), "struck by the nearest scene alone");
    assert!(model(&[0, 1]).dominated_near(0, &query, |_| true), "beaten on most of the weight, yet kept");
    // On a measured scene, that scene alone decides (as the prediction is that measurement).
    assert!(model(&[0]).dominated_near(0, &scene(0.15), |_| true));
    assert!(!model(&[1, 2]).dominated_near(0, &scene(0.15), |_| true));
}

/// The cost guard of issue 40: a pick predicted at over 10x another candidate's time says what
/// a tenth of its time would buy. On s23_sphere_dense only lpm preview (2.8 s) reaches 0.10
/// and photon-grid's draft takes 0.13 s; on s01_thin_sun the pick, lpm draft, is the cheapest.
#[test]
fn a_costly_pick_says_what_a_tenth_of_its_time_would_buy() {
    let model = model();
    let costly = pick(model, &features_of(model, "s23_sphere_dense"), 0.1, 0.0, registry::preset_settings);
    assert_eq!((costly.solver.as_str(), costly.quality.as_str()), ("lpm", "preview"), "{}", costly.why);
    let tenth = costly.predicted_seconds.unwrap() / 10.0;
    let clause = costly.why.split("; in a tenth of its time ").nth(1).unwrap_or_else(|| panic!("no cheaper option named: {}", costly.why));
    let seconds: f64 = clause.split(" in ").nth(1).and_then(|x| x.split(" s").next()).and_then(|x| x.parse().ok()).unwrap_or(f64::NAN);
    assert!(seconds <= tenth, "{clause} (a tenth: {tenth})");
    let cheap = pick(model, &features_of(model, "s01_thin_sun"), 0.1, 0.0, registry::preset_settings);
    assert!(!cheap.why.contains("in a tenth of its time"), "{}", cheap.why);
    // With a budget the pick is already the trade: no such clause.
    let budget = pick(model, &features_of(model, "s23_sphere_dense"), 0.1, 0.5, registry::preset_settings);
    assert!(!budget.why.contains("in a tenth of its time"), "{}", budget.why);
}
