//! Writing the model's data: the provisional measurements (the solver fixtures' scenes, every
//! solver at its registry presets, until scripts/bench_solvers.py's file replaces them) and the
//! measured scenes' features, which the model needs whichever file it is.

use crate::solvers::SolveCtx;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde_json::{json, Value};

use super::features::Features;
use super::model::{FeatureTable, Measurements};
use crate::scene::Scene;
use crate::solvers::registry::SOLVERS;
use crate::solvers::testing::{fixture_scene, load_fixture, selected, Errors, SolverOutput};

fn here(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src/pipeline/auto").join(file)
}

/// The fixtures measured for the provisional file: distant light on cubes of g 0 / 0.7 / 0.9
/// and on the plume, the dense cloud, a point, spot and rect light beside the plume, a point
/// light inside a sphere, the plume under a sun-sky dome, the milk cube under it.
const FIXTURES: [&str; 9] = ["cube_g0", "cube_g07", "cube_g09", "plume", "cloud", "plume_point", "fig10_g08", "dome_sun", "dome_milk"];

/// A preset is skipped when the previous (cheaper) preset of the same solver took longer than
/// this many seconds: the next costs 4-16x more (lpm's final preset took 18 minutes on cube g 0
/// on the loaded machine), and the pick needs no configuration that slow to rank it last.
const SKIP_AFTER_SECONDS: f64 = 4.0;
/// A run still going after this many seconds is cancelled (through `Progress::cancelled`) and
/// left out of the file: the provisional measurements must fit in half an hour of the shared
/// machine. The pick then never chooses it, which only costs accuracy it could have bought.
const CANCEL_AFTER_SECONDS: f64 = 12.0;

/// Cancels a solve once its time is up.
struct TimeLimit(Instant);
impl crate::stages::Progress for TimeLimit {
    fn update(&self, _: &str, _: f32) -> bool {
        !self.cancelled()
    }
    fn cancelled(&self) -> bool {
        self.0.elapsed().as_secs_f64() > CANCEL_AFTER_SECONDS
    }
}

/// Regenerates measurements.json from the fixtures (`AUTO_CASE` selects fixtures by substring:
/// then only those are re-measured and the others' runs kept). Minutes: run with
/// `cargo nextest run --cargo-profile release -p volscatter-core regenerate_auto_measurements
/// --run-ignored only`, then bless the features (`scene_features_are_up_to_date`).
#[test]
#[ignore]
fn regenerate_auto_measurements() {
    let path = here("measurements.json");
    let old: Option<Measurements> = std::fs::read_to_string(&path).ok().and_then(|t| Measurements::parse(&t).ok());
    let chosen: Vec<&str> = selected(&FIXTURES, "AUTO_CASE").collect();
    let mut scenes = Vec::new();
    let mut runs: Vec<Value> = Vec::new();
    for name in FIXTURES {
        // Written after every scene: a long run stopped part-way keeps what it measured.
        if !scenes.is_empty() {
            write_measurements(&path, &scenes, &runs);
        }
        let fx = load_fixture(name);
        scenes.push(json!({"name": name, "fixture": name, "reference_noise": fx.noise_image}));
        if !chosen.contains(&name) {
            if let Some(old) = &old {
                runs.extend(old.runs.iter().filter(|r| r.scene == name).map(|r| {
                    json!({"scene": r.scene, "solver": r.solver, "quality": r.quality, "settings": r.settings, "device": r.device,
                           "seconds": r.seconds, "solve_seconds": r.solve_seconds, "composite_seconds": r.composite_seconds,
                           "image_error": r.image_error, "grid_error": r.grid_error})
                }));
            }
            continue;
        }
        let sc = fixture_scene(name);
        for entry in SOLVERS.iter().filter(|e| e.name != super::NAME) {
            let mut previous = 0.0;
            for preset in entry.presets {
                if previous > SKIP_AFTER_SECONDS {
                    eprintln!("{name} {} {}: skipped (the previous preset took {previous:.1} s)", entry.name, preset.name);
                    continue;
                }
                let settings = preset.settings();
                let t = Instant::now();
                let out = entry.build(&settings).and_then(|s| s.solve(&sc, &mut SolveCtx::new(&TimeLimit(t))));
                let solve = t.elapsed().as_secs_f64();
                let out = match out {
                    Ok(o) => o,
                    Err(e) => {
                        eprintln!("{name} {} {}: {e} after {solve:.1} s", entry.name, preset.name);
                        previous = solve;
                        continue;
                    }
                };
                let t = Instant::now();
                let o = SolverOutput::of(&sc, &out.scattering);
                let composite = t.elapsed().as_secs_f64();
                let e = Errors::against(&o, &fx);
                previous = solve + composite;
                eprintln!("{name:12} {:12} {:8} {:7.2} s  {e}", entry.name, preset.name, solve + composite);
                runs.push(json!({"scene": name, "solver": entry.name, "quality": preset.name, "settings": settings, "device": "cpu",
                    "seconds": solve + composite, "solve_seconds": solve, "composite_seconds": composite,
                    "image_error": e.image, "grid_error": e.grid}));
            }
        }
    }
    write_measurements(&path, &scenes, &runs);
}

fn write_measurements(path: &Path, scenes: &[Value], runs: &[Value]) {
    let threads = rayon::current_num_threads();
    let doc = json!({
        "format": 1,
        "written_by": "core/src/pipeline/auto/measure.rs regenerate_auto_measurements (provisional: the solver fixtures, until scripts/bench_solvers.py writes this file)",
        "machine": format!("{threads} rayon threads on the shared development machine ({} cores), timings noisy", std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0)),
        "date": date(),
        "error": "image_error: relative RMSE of the composited image (transparent background) against the fixture's converged reference; grid_error: of the scattering grid on the fixture's 10^3 frame",
        "scenes": scenes,
        "runs": runs,
        "cycles": [],
    });
    std::fs::write(path, serde_json::to_string_pretty(&doc).unwrap() + "\n").unwrap();
}

fn date() -> String {
    std::process::Command::new("date")
        .args(["-u", "+%Y-%m-%d"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// The scene of a measured scene: a fixture's, or the file at `scene` (relative to the
/// repository root).
fn measured_scene(s: &super::model::MeasuredScene) -> Scene {
    match (&s.fixture, &s.scene) {
        (Some(f), _) => fixture_scene(f),
        (None, Some(p)) => {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(p);
            Scene::load(&path).unwrap_or_else(|e| panic!("measured scene {} ({}): {e}", s.name, path.display()))
        }
        (None, None) => panic!("measured scene {} names neither a scene file nor a fixture", s.name),
    }
}

/// scene_features.json holds the features of exactly the measured scenes, as `Features::of`
/// computes them now (relative 1e-6: the JSON round trip of f32 sums). With VOLSCATTER_BLESS=1
/// it is rewritten instead.
#[test]
fn scene_features_are_up_to_date() {
    let m = Measurements::parse(include_str!("measurements.json")).unwrap();
    let mut table = FeatureTable { format: 1, ..Default::default() };
    for s in &m.scenes {
        table.scenes.insert(s.name.clone(), Features::of(&measured_scene(s)));
    }
    let path = here("scene_features.json");
    if std::env::var("VOLSCATTER_BLESS").is_ok() {
        std::fs::write(&path, serde_json::to_string_pretty(&table).unwrap() + "\n").unwrap();
        return;
    }
    let stored: FeatureTable = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(stored.scenes.keys().collect::<Vec<_>>(), table.scenes.keys().collect::<Vec<_>>(), "measured scenes and features differ: bless");
    for (name, f) in &table.scenes {
        let g = &stored.scenes[name];
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1e-12);
        assert!(
            close(f.tau_mean, g.tau_mean) && close(f.tau_max, g.tau_max) && close(f.albedo, g.albedo) && close(f.g, g.g) && f.lights == g.lights && f.lamps == g.lamps && close(f.voxels, g.voxels) && close(f.pixels, g.pixels),
            "{name}: features now {f:?}, stored {g:?} (bless with VOLSCATTER_BLESS=1)"
        );
    }
}
