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

/// `volscatter solvers --json` prints the registry, exactly the document of `registry::to_json`
/// (and of `vs_solvers_json`).
#[test]
fn solvers_prints_the_registry_as_json() {
    let o = bin().args(["solvers", "--json"]).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is JSON");
    assert_eq!(doc, volscatter_core::solvers::registry::to_json());
    let names: Vec<&str> = doc["solvers"].as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names, volscatter_core::solvers::registry::SOLVER_NAMES);
}

/// `volscatter solvers` is for people: one row per solver (name, GPU, lights, what it is for),
/// not the registry's JSON.
#[test]
fn solvers_prints_a_table_for_people() {
    let o = bin().arg("solvers").output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(serde_json::from_str::<serde_json::Value>(&text).is_err(), "a table, not JSON:\n{text}");
    assert!(text.starts_with("solver "), "{text}");
    for name in volscatter_core::solvers::registry::SOLVER_NAMES {
        let row = text.lines().find(|l| l.starts_with(&format!("{name} "))).unwrap_or_else(|| panic!("no row for {name}:\n{text}"));
        assert!(row.contains("yes") || row.contains("no"), "{row}");
    }
    assert!(text.lines().count() < 40, "{} lines", text.lines().count());
}

/// Headless (no XDG_RUNTIME_DIR), Mesa's Vulkan device-selection layer made libwayland print
/// "error: XDG_RUNTIME_DIR is invalid or not set" at each adapter enumeration; the CLI switches
/// the layer off there. Meaningful where Mesa's Vulkan drivers are installed (CI installs them).
#[test]
fn gpu_probing_prints_no_wayland_error_headless() {
    let o = bin().arg("gpu-info").env_remove("XDG_RUNTIME_DIR").env_remove("NODEVICE_SELECT").env_remove("WAYLAND_DISPLAY").output().unwrap();
    assert!(!stderr(&o).contains("XDG_RUNTIME_DIR"), "{}", stderr(&o));
}

/// A successful render says each thing once and nothing alarming: where Mesa's software adapter is
/// installed (CI), `--device auto` leaves it for the CPU and both the solve and the composite noted
/// that, so the note was printed twice.
#[test]
fn a_successful_render_prints_each_note_once() {
    let dir = tmp("notes");
    let path = dir.join("scene.json");
    std::fs::write(&path, serde_json::to_string(&small_scene()).unwrap()).unwrap();
    // Not -q: it leaves the notes out.
    let o = bin()
        .arg("render")
        .arg(&path)
        .args(["--out", dir.join("o.exr").to_str().unwrap(), "--solver", "pop", "--device", "auto"])
        .args(["--set", "grid_resolution=8", "--set", "output_resolution=16"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    let notes: Vec<&str> = e.lines().filter(|l| l.starts_with("note:")).collect();
    for n in &notes {
        assert_eq!(notes.iter().filter(|m| *m == n).count(), 1, "printed more than once: {n}\n{e}");
    }
    assert!(!e.to_lowercase().contains("error:"), "{e}");
}

/// `compare --device`: pop solves (and composites) on the device asked for, recorded per run in
/// the JSON. No adapter is visible with WGPU_BACKEND=metal (none on Linux): `gpu` is then a
/// device error (exit 1), `auto` runs on the CPU. Unknown solvers are refused with the
/// registry's list.
#[test]
fn compare_runs_on_the_device_asked_for() {
    if cfg!(target_os = "macos") {
        println!("SKIPPED: Metal exists on macOS, so WGPU_BACKEND=metal does not hide the adapter");
        return;
    }
    let dir = tmp("compare-device");
    let scene = dir.join("scene.json");
    std::fs::write(&scene, serde_json::to_string(&small_scene()).unwrap()).unwrap();
    let compare = |device: &str, solvers: &str| {
        let json = dir.join(format!("{device}.json"));
        let o = bin()
            .env("WGPU_BACKEND", "metal")
            .args(["compare", "--solvers", solvers, "--no-grid", "-q", "--width", "8", "--height", "6", "--device", device])
            .args(["--set", "pop.grid_resolution=8", "--set", "pop.max_iterations=20", "--set", "pop.output_resolution=16"])
            .arg("--json")
            .arg(&json)
            .arg(&scene)
            .output()
            .unwrap();
        (o, json)
    };
    for device in ["cpu", "auto"] {
        let (o, json) = compare(device, "pop,reference@1");
        assert!(o.status.success(), "--device {device}: {}", stderr(&o));
        let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        assert_eq!(doc["runs"][0]["solver"], "pop");
        assert_eq!(doc["runs"][0]["device"], "cpu", "--device {device} without an adapter");
    }
    let (o, _) = compare("gpu", "pop,reference@1");
    assert_clean_failure(&o, "device: no GPU adapter");
    let (o, _) = compare("cpu", "popp,reference@1");
    let known = volscatter_core::solvers::registry::SOLVER_NAMES.join(", ");
    assert_clean_failure(&o, &format!("unknown solver `popp` (known: {known})"));
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

/// Issue 22: `--out /dev/full` reported success with nothing written.
#[test]
fn a_full_disk_is_an_error() {
    if !std::path::Path::new("/dev/full").exists() {
        eprintln!("skipped: /dev/full does not exist here");
        return;
    }
    let dir = tmp("full");
    let path = dir.join("scene.json");
    std::fs::write(&path, serde_json::to_string(&small_scene()).unwrap()).unwrap();
    let o = bin().arg("render").arg(&path).args(["--out", "/dev/full", "-q", "--spp", "1"]).output().unwrap();
    assert_clean_failure(&o, "No space left");
    // The PNG preview goes through the same checked write.
    let o = bin().arg("render").arg(&path).arg("--out").arg(dir.join("o.exr")).args(["--png", "/dev/full", "-q", "--spp", "1"]).output().unwrap();
    assert_clean_failure(&o, "No space left");
}

/// Issue 22: a FIFO given as `medium.vdb` blocked the CLI forever (it waited for a writer).
/// Refused now as "not a regular file"; a run still going after 20 s counts as the hang.
#[test]
fn a_fifo_as_medium_is_refused_not_waited_on() {
    let dir = tmp("fifo");
    let fifo = dir.join("medium.vdb");
    let _ = std::fs::remove_file(&fifo);
    match Command::new("mkfifo").arg(&fifo).status() {
        Ok(s) if s.success() => {}
        _ => {
            eprintln!("skipped: mkfifo is not available");
            return;
        }
    }
    let mut scene = small_scene();
    scene["medium"] = serde_json::json!({"vdb": "medium.vdb"});
    let path = dir.join("scene.json");
    std::fs::write(&path, serde_json::to_string(&scene).unwrap()).unwrap();
    let mut child = bin()
        .arg("render")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("o.exr"))
        .arg("-q")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed().as_secs() > 20 {
            child.kill().unwrap();
            panic!("the CLI is still waiting on the FIFO after 20 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    assert_clean_failure(&o, "not a regular file");
}
