//! The registry against the settings structs and constructors it describes. The tables are
//! generated from the structs (`settings!`), so what can still go wrong is checked here: a
//! default outside its own range or of another JSON type, a constructor that does not validate
//! (or refuses a value naming another setting), a range end off by one, a cross-field check
//! refusing what the table says is fine, a preset that does not build, a help of several lines.

use super::*;
use serde_json::Map;

fn defaults_of(entry: &SolverEntry) -> Map<String, Value> {
    match (entry.defaults)() {
        Value::Object(m) => m,
        other => panic!("{}: defaults are not an object: {other}", entry.name),
    }
}

/// The defaults with `key` set to `value`, through the entry's constructor (parse + validate).
fn accepts(entry: &SolverEntry, key: &str, value: Value) -> bool {
    let mut m = defaults_of(entry);
    m.insert(key.into(), value.clone());
    match entry.validate(&m) {
        Ok(_) => true,
        Err(Error::Scene { field, .. }) => {
            // A refusal must name the setting it refuses, not another one.
            assert_eq!(field, format!("solver.{key}"), "{}: {key} = {value} refused for another field", entry.name);
            false
        }
        Err(e) => panic!("{}: {key} = {value}: unexpected error {e}", entry.name),
    }
}

fn number(kind: SettingType, v: f64) -> Value {
    match kind {
        SettingType::Int => Value::from(v as u64),
        _ => Value::from(v),
    }
}

#[test]
fn settings_tables_name_every_field_of_their_struct_with_its_type() {
    for entry in SOLVERS {
        let defaults = defaults_of(entry);
        let mut table: Vec<&str> = entry.settings.iter().map(|s| s.name).collect();
        let mut fields: Vec<&str> = defaults.keys().map(String::as_str).collect();
        table.sort_unstable();
        fields.sort_unstable();
        assert_eq!(table, fields, "{}: registry settings and the settings struct's fields differ", entry.name);
        for s in entry.settings {
            let d = &defaults[s.name];
            let type_ok = match s.kind {
                SettingType::Int => d.is_u64(),
                SettingType::Float => d.is_f64(),
                SettingType::Bool => d.is_boolean(),
                SettingType::Choice => d.as_str().is_some_and(|v| s.choices.contains(&v)),
            };
            assert!(type_ok, "{}.{}: default {d} is not of type {:?}", entry.name, s.name, s.kind);
            assert!(!s.help.is_empty() && !s.help.contains('\n'), "{}.{}: help must be one line", entry.name, s.name);
        }
        // The defaults themselves build a solver.
        entry.validate(&defaults).unwrap_or_else(|e| panic!("{}: defaults refused: {e}", entry.name));
    }
}

/// Every range in the table is the one `validate()` applies: both ends (and 0 where it stands
/// for a derived value) are accepted, the first values outside refused. Settings without a
/// range accept 0 and a large value: a check in `validate()` the table lacks fails here.
#[test]
fn ranges_match_validate() {
    for entry in SOLVERS {
        for s in entry.settings {
            let what = format!("{}.{}", entry.name, s.name);
            match (s.kind, s.range) {
                (SettingType::Bool, _) => {
                    assert!(accepts(entry, s.name, Value::Bool(false)) && accepts(entry, s.name, Value::Bool(true)), "{what}");
                }
                (SettingType::Choice, _) => {
                    for c in s.choices {
                        assert!(accepts(entry, s.name, Value::from(*c)), "{what}: choice {c} refused");
                    }
                    assert!(!accepts(entry, s.name, Value::from("no such choice")), "{what}");
                }
                (kind, None) => {
                    let big = if kind == SettingType::Int { u32::MAX as f64 } else { 1e30 };
                    for v in [0.0, 1.0, big] {
                        assert!(accepts(entry, s.name, number(kind, v)), "{what}: {v} refused but the table has no range");
                    }
                }
                (kind, Some(r)) => {
                    // The step to the first value outside: 1 for integers, a relative 1e-3
                    // for floats (far above f32 rounding, far below any range's width).
                    let step = |v: f64| if kind == SettingType::Int { 1.0 } else { (v.abs() * 1e-3).max(1e-6) };
                    if let Some(min) = r.min {
                        let inside = if r.min_exclusive { min + step(min) } else { min };
                        assert!(accepts(entry, s.name, number(kind, inside)), "{what}: {inside} (lower end) refused");
                        let outside = if r.min_exclusive { min } else { min - step(min) };
                        let zero_allowed = s.zero.is_some() && outside == 0.0;
                        if outside >= 0.0 || kind == SettingType::Float {
                            assert_eq!(accepts(entry, s.name, number(kind, outside)), zero_allowed, "{what}: {outside} (below the range)");
                        }
                    }
                    if let Some(max) = r.max {
                        let inside = if r.max_exclusive { max - step(max) } else { max };
                        assert!(accepts(entry, s.name, number(kind, inside)), "{what}: {inside} (upper end) refused");
                        let outside = if r.max_exclusive { max } else { max + step(max) };
                        assert!(!accepts(entry, s.name, number(kind, outside)), "{what}: {outside} (above the range) accepted");
                    } else {
                        assert!(accepts(entry, s.name, number(kind, 1e30)), "{what}: unbounded above, yet 1e30 refused");
                    }
                    if let Some(means) = s.zero {
                        assert!(accepts(entry, s.name, number(kind, 0.0)), "{what}: 0 ({means}) refused");
                    }
                }
            }
        }
    }
}

#[test]
fn presets_build_their_solver_and_name_only_its_settings() {
    for entry in SOLVERS {
        assert!(!entry.presets.is_empty(), "{}: no presets", entry.name);
        for p in entry.presets.iter().chain([&entry.test]) {
            let parsed: Value = serde_json::from_str(p.settings_json).unwrap_or_else(|e| panic!("{}/{}: {e}", entry.name, p.name));
            assert!(parsed.is_object() && !p.settings().is_empty(), "{}/{}: not a settings object", entry.name, p.name);
            for key in p.settings().keys() {
                assert!(entry.settings.iter().any(|s| s.name == key), "{}/{}: `{key}` is no setting", entry.name, p.name);
            }
            entry.validate(&p.settings()).unwrap_or_else(|e| panic!("{}/{}: refused: {e}", entry.name, p.name));
        }
    }
    // The hosts offer one Quality menu for every solver: the same preset names everywhere.
    let names = |e: &SolverEntry| e.presets.iter().map(|p| p.name).collect::<Vec<_>>();
    for e in SOLVERS {
        assert_eq!(names(e), names(&SOLVERS[0]), "{}: preset names differ from {}", e.name, SOLVERS[0].name);
    }
}

/// Every solver has a `test` preset, found by name, and it stays out of the hosts' menu (the
/// presets of the JSON).
#[test]
fn every_solver_has_a_test_preset_outside_the_hosts_menu() {
    for entry in SOLVERS {
        let test = entry.preset("test").unwrap_or_else(|| panic!("{}: no test preset", entry.name));
        assert_eq!((test.name, test.settings_json), ("test", entry.test.settings_json), "{}", entry.name);
        assert!(entry.presets.iter().all(|p| p.name != "test"), "{}: test preset in the hosts' menu", entry.name);
        assert!(entry.preset("no such preset").is_none());
    }
    for s in to_json()["solvers"].as_array().unwrap() {
        assert!(s["presets"].as_array().unwrap().iter().all(|p| p["name"] != "test"), "{}: test preset in the JSON", s["name"]);
    }
}

/// Help is what a host shows as a tooltip: one line, one sentence, no measurement log (those
/// live in docs/solvers/<name>.md).
#[test]
fn help_strings_are_short_single_sentences() {
    for entry in SOLVERS {
        let helps = std::iter::once((entry.name, entry.help)).chain(entry.settings.iter().map(|s| (s.name, s.help)));
        for (what, help) in helps {
            let what = format!("{}.{what}", entry.name);
            assert!(!help.is_empty() && !help.contains('\n'), "{what}: help must be one line");
            assert!(help.len() <= 200, "{what}: help of {} characters: move the detail to docs/solvers/{}.md", help.len(), entry.name);
            assert!(!help.trim_end_matches('.').contains(". "), "{what}: help of several sentences: {help}");
        }
    }
}

/// The generated range check: the ends as declared, 0 where it stands for a derived value, a
/// non-finite float refused, and a message that says the range.
#[test]
fn setting_check_refuses_outside_its_range_and_says_why() {
    let spec = |range, zero| SettingSpec { name: "x", kind: SettingType::Float, range, zero, choices: &[], help: "h" };
    let half_open = Range { min: Some(0.0), max: Some(1.0), min_exclusive: false, max_exclusive: true };
    let s = spec(Some(half_open), None);
    assert!(s.check(Some(0.0)).is_ok() && s.check(Some(0.999)).is_ok() && s.check(None).is_ok());
    let e = s.check(Some(1.0)).unwrap_err();
    assert!(matches!(&e, Error::Scene { field, .. } if field == "solver.x"), "{e}");
    assert!(e.to_string().contains("must be in [0, 1), got 1"), "{e}");
    assert!(s.check(Some(-1e-9)).is_err() && s.check(Some(f64::NAN)).is_err() && s.check(Some(f64::INFINITY)).is_err());
    let z = spec(Some(Range::closed(2.0, 8.0)), Some("derived"));
    assert!(z.check(Some(0.0)).is_ok() && z.check(Some(2.0)).is_ok() && z.check(Some(8.0)).is_ok());
    let e = z.check(Some(1.0)).unwrap_err().to_string();
    assert!(e.contains("must be 0 (derived) or in [2, 8], got 1"), "{e}");
    let unbounded = spec(Some(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }), None);
    assert!(unbounded.check(Some(1e30)).is_ok() && unbounded.check(Some(0.0)).is_err());
    assert!(unbounded.check(Some(0.0)).unwrap_err().to_string().contains("must be > 0"));
}

#[test]
fn names_lookup_and_json_form() {
    assert_eq!(SOLVER_NAMES, SOLVERS.iter().map(|s| s.name).collect::<Vec<_>>().as_slice());
    assert_eq!(SOLVER_NAMES[..2], ["reference", "pop"]);
    assert_eq!(get("pop").unwrap().name, "pop");
    let e = get("pops").err().expect("unknown name accepted").to_string();
    assert!(e.contains("pops") && e.contains("reference, pop"), "{e}");
    assert!(super::build("nope", &Map::new()).is_err());
    let j = to_json();
    assert_eq!(j["format"], 1);
    let pop = j["solvers"].as_array().unwrap().iter().find(|s| s["name"] == "pop").expect("pop listed");
    assert_eq!(pop["gpu"], true);
    assert_eq!(pop["lights"], serde_json::json!(["distant", "point", "spot", "rect", "disk", "dome", "emission"]));
    let grid = pop["settings"].as_array().unwrap().iter().find(|s| s["name"] == "grid_resolution").unwrap();
    assert_eq!(grid["default"], 32);
    assert_eq!(grid["type"], "int");
    assert_eq!(grid["range"], serde_json::json!({"min": 2.0, "max": 512.0}));
    let merge = pop["settings"].as_array().unwrap().iter().find(|s| s["name"] == "merge_resolution").unwrap();
    assert_eq!(merge["zero"], "twice grid_resolution");
    assert_eq!(pop["presets"][2]["settings"]["max_iterations"], 1000);
    let types: Vec<&str> = j["light_types"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(types, LightType::ALL.map(LightType::name));
    // The serde names of LightType are the scene JSON's names.
    assert_eq!(serde_json::to_value(LightType::ALL).unwrap(), serde_json::json!(types));
}

#[test]
fn range_contains_respects_open_ends() {
    let r = Range { min: Some(0.0), max: Some(1.0), min_exclusive: true, max_exclusive: false };
    assert!(!r.contains(0.0) && r.contains(1e-9) && r.contains(1.0) && !r.contains(1.0 + 1e-9));
    assert!(Range::closed(2.0, 4.0).contains(2.0) && !Range::closed(2.0, 4.0).contains(4.5));
}

/// Every solver's `test` preset solves a small lit box, quickly, to a finite, non-negative,
/// non-zero S: small settings that still run the whole solver.
#[test]
fn test_presets_solve_a_small_scene() {
    use crate::scene::{Camera, Light, Scene};
    use glam::Vec3;
    let scene = Scene {
        medium: super::super::testing::homogeneous_box(8, 0.125, 4.0, 0.9, 0.6),
        lights: vec![Light::Distant { direction: Vec3::new(0.3, 0.2, -1.0).normalize(), irradiance: Vec3::ONE, half_angle: 0.0 }],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, 12, 12),
        solver: Default::default(),
    };
    for entry in SOLVERS {
        let t = std::time::Instant::now();
        // Through the pipeline, as hosts solve (auto picks a solver there).
        let solved = crate::pipeline::solve(&scene, entry.name, &entry.test.settings(), crate::pipeline::Devices::cpu(), &crate::stages::NoProgress);
        let out = solved.unwrap_or_else(|e| panic!("{}: {e}", entry.name)).output;
        let s = &out.scattering.data;
        assert!(!s.is_empty() && s.iter().all(|v| v.is_finite() && v.min_element() >= 0.0), "{}: S not finite and >= 0", entry.name);
        assert!(s.iter().map(|v| v.x).sum::<f32>() > 0.0, "{}: S is zero", entry.name);
        eprintln!("{}: test preset {:.2} s", entry.name, t.elapsed().as_secs_f64());
    }
}
