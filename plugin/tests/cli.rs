//! The `volscatter` binary on good and bad input: bad input gets exit code 1 and a message
//! naming the field or file, never a panic (exit code 101) or a signal.

use std::path::PathBuf;
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_volscatter"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vs-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A valid small scene (the default one, shrunk), to mutate.
fn small_scene() -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_str(volscatter_core::scene::DEFAULT_SCENE_JSON).unwrap();
    v["camera"]["width"] = 24.into();
    v["camera"]["height"] = 16.into();
    v["medium"]["dims"] = serde_json::json!([24]);
    v
}

fn render_json(scene: &serde_json::Value, dir: &std::path::Path, extra: &[&str]) -> Output {
    let path = dir.join("scene.json");
    std::fs::write(&path, serde_json::to_string(scene).unwrap()).unwrap();
    bin().arg("render").arg(&path).arg("--out").arg(dir.join("o.exr")).arg("-q").args(extra).output().unwrap()
}

fn assert_clean_failure(o: &Output, needle: &str) {
    assert_eq!(o.status.code(), Some(1), "expected exit 1, got {:?}: {}", o.status, stderr(o));
    let e = stderr(o);
    assert!(e.contains(needle), "message should name `{needle}`: {e}");
    assert!(!e.contains("panicked"), "{e}");
}

#[test]
fn renders_a_scene_with_png_and_report() {
    let dir = tmp("ok");
    let o = render_json(
        &small_scene(),
        &dir,
        &["--spp", "2", "--png", dir.join("o.png").to_str().unwrap(), "--report", dir.join("r.json").to_str().unwrap()],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let img = volscatter_core::io::exr::read_rgba(&dir.join("o.exr")).unwrap();
    assert_eq!((img.width, img.height), (24, 16));
    assert!(img.stats().mean_alpha > 0.01);
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    assert!(report["phases_seconds"]["path tracing"].as_f64().unwrap() > 0.0);
    assert_eq!(report["settings"]["spp"], 2);
    assert!(std::fs::metadata(dir.join("o.png")).unwrap().len() > 100);
}

#[test]
fn bad_scenes_fail_cleanly_naming_the_field() {
    let dir = tmp("bad");
    let mut s = small_scene();
    s["lights"][0]["type"] = "laser".into();
    assert_clean_failure(&render_json(&s, &dir, &[]), "lights[0]");

    let mut s = small_scene();
    s["camera"]["width"] = 1_000_000.into();
    s["camera"]["height"] = 1_000_000.into();
    assert_clean_failure(&render_json(&s, &dir, &[]), "camera.width");

    let mut s = small_scene();
    s["medium"]["albedo"] = serde_json::json!([0.5, -0.1, 0.5]);
    assert_clean_failure(&render_json(&s, &dir, &[]), "medium.albedo");

    let mut s = small_scene();
    s["lights"][1]["texture"] = "no-such-sky.exr".into();
    assert_clean_failure(&render_json(&s, &dir, &[]), "no-such-sky.exr");

    let mut s = small_scene();
    s["medium"] = serde_json::json!({"raw": "missing.f32", "dims": [4, 4, 4]});
    assert_clean_failure(&render_json(&s, &dir, &[]), "missing.f32");

    let mut s = small_scene();
    s.as_object_mut().unwrap().remove("camera");
    assert_clean_failure(&render_json(&s, &dir, &[]), "camera");

    assert_clean_failure(&render_json(&small_scene(), &dir, &["--spp", "0"]), "spp");
    assert_clean_failure(&render_json(&small_scene(), &dir, &["--solver", "magic"]), "magic");

    let path = dir.join("broken.json");
    std::fs::write(&path, "{\"format\": 1, \"medium\": ").unwrap();
    let o = bin().arg("render").arg(&path).arg("-q").output().unwrap();
    assert_clean_failure(&o, "broken.json");
    let o = bin().args(["render", "/nonexistent/scene.json", "-q"]).output().unwrap();
    assert_clean_failure(&o, "/nonexistent/scene.json");
}

/// `--aov`: the EXR holds the layers asked for (default: background only) whatever the solver,
/// the single-scattering grid is computed (and timed) only for single or multiple, and an
/// unknown name fails cleanly. Layer names are found in the EXR header's channel list.
#[test]
fn aov_layers_are_opt_in() {
    let dir = tmp("aov");
    let has = |layer: &str| {
        let bytes = std::fs::read(dir.join("o.exr")).unwrap();
        let needle = format!("{layer}.R");
        bytes.windows(needle.len()).any(|w| w == needle.as_bytes())
    };
    let phases = || -> serde_json::Value {
        let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
        report["phases_seconds"].clone()
    };
    let report = dir.join("r.json");
    let report = report.to_str().unwrap();
    for (solver, extra) in [("pop", vec![]), ("reference", vec!["--spp", "1"])] {
        let mut args = vec!["--solver", solver, "--report", report];
        args.extend(&extra);
        let o = render_json(&small_scene(), &dir, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(has("background") && !has("single") && !has("multiple"), "{solver}: default layers");
        assert!(phases().get("composite: single-scattering AOV").is_none(), "{solver}: single-scattering grid computed without its AOVs");
        args.extend(["--aov", "single,multiple"]);
        let o = render_json(&small_scene(), &dir, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(!has("background") && has("single") && has("multiple"), "{solver}: --aov single,multiple");
        if solver == "pop" {
            assert!(phases()["composite: single-scattering AOV"].as_f64().unwrap() > 0.0);
        }
    }
    assert_clean_failure(&render_json(&small_scene(), &dir, &["--aov", "singel"]), "singel");
}
