//! The extreme-value scenes of `volscatter_tests::extreme` through the `volscatter` CLI (issue
//! 22): each ends with exit 0 and a finite image, or exit 1 and a message on stderr; never a
//! panic (exit 101), a signal (an allocation abort), or a run past the limit.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use volscatter_tests::cdylib::{cli_binary, scratch_dir};
use volscatter_tests::extreme::{cases, TEST_BUDGET};

/// As in extreme_abi.rs: 20x what any case takes when it runs.
const CASE_LIMIT: Duration = Duration::from_secs(20);

#[test]
fn extreme_scenes_through_the_cli_end_cleanly() {
    let dir = scratch_dir("extreme-cli");
    let budget = TEST_BUDGET.to_string();
    let bin = cli_binary(); // built (when stale) before any case is timed
    let mut n = 0;
    for (i, (name, scene)) in cases(&dir).into_iter().enumerate() {
        let path = dir.join(format!("case{i}.json"));
        std::fs::write(&path, scene.to_string()).unwrap();
        let out_exr = dir.join(format!("case{i}.exr"));
        let t = Instant::now();
        let mut child = Command::new(bin)
            .args(["render", "-q", "--device", "cpu", "--memory-budget", &budget, "--out"])
            .arg(&out_exr)
            .arg(&path)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let status = loop {
            if let Some(st) = child.try_wait().unwrap() {
                break st;
            }
            if t.elapsed() > CASE_LIMIT {
                let _ = child.kill();
                panic!("{name}: still running after {CASE_LIMIT:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let stderr = child.wait_with_output().map(|o| String::from_utf8_lossy(&o.stderr).into_owned()).unwrap_or_default();
        match status.code() {
            Some(0) => {
                let img = volscatter_core::io::exr::read_rgba(&out_exr).unwrap_or_else(|e| panic!("{name}: exit 0 but {e}"));
                assert!(img.rgba.iter().all(|p| p.is_finite()), "{name}: exit 0 with a non-finite image");
            }
            Some(1) => assert!(stderr.contains("error: ") && !stderr.contains("panicked"), "{name}: {stderr}"),
            other => panic!("{name}: exit {other:?} (a panic or a signal): {stderr}"),
        }
        if name.contains("over the budget") {
            assert!(stderr.contains("memory budget is 1.0 GiB"), "{name}: {stderr}");
        }
        n += 1;
    }
    assert!(n >= 30, "{n} cases");
}

/// A scene whose lpm solve runs out of core (scratch files in TMPDIR) for minutes unless stopped.
fn long_out_of_core_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("long_ooc.json");
    let scene = r#"{"format": 1, "medium": {"procedural": "plume", "dims": [48], "density_scale": 10.0, "albedo": 0.99},
        "lights": [{"type": "distant", "direction": [0, 0, -1], "irradiance": 1.0}],
        "camera": {"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12},
        "solver": {"name": "lpm", "out_of_core": true, "first_order": "boundary", "grid_resolution": 48,
                   "max_orders": 100000, "epsilon": 1e-12}}"#;
    std::fs::write(&path, scene).unwrap();
    path
}

/// SIGINT, SIGTERM and SIGHUP (Ctrl-C, `timeout` and farm managers, a closed terminal) during
/// an out-of-core solve: the CLI cancels it and exits with 128 + the signal's number, saying
/// so, with no image written and no scratch file left in TMPDIR. Signals are sent with
/// `kill(1)`; skipped where there is none.
#[cfg(unix)]
#[test]
fn harden_cli_signals_cancel_the_solve_and_leave_nothing() {
    if !std::process::Command::new("kill").arg("-l").output().is_ok_and(|o| o.status.success()) {
        eprintln!("skipped: no kill(1) to send signals with");
        return;
    }
    let dir = scratch_dir("cli-signals");
    let scene = long_out_of_core_scene(&dir);
    let bin = cli_binary();
    for (sig, n) in [("INT", 2), ("TERM", 15), ("HUP", 1)] {
        let tmp = dir.join(format!("tmp-{sig}"));
        std::fs::create_dir_all(&tmp).unwrap();
        let out = dir.join(format!("{sig}.exr"));
        let child = Command::new(bin)
            .args(["render", "-q", "--device", "cpu", "--out"])
            .arg(&out)
            .arg(&scene)
            .env("TMPDIR", &tmp)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Into the solve (the scene loads in milliseconds; the solve takes minutes).
        std::thread::sleep(Duration::from_millis(1500));
        let sent = Command::new("kill").arg(format!("-{sig}")).arg(child.id().to_string()).status().unwrap();
        assert!(sent.success(), "kill -{sig}");
        let t = Instant::now();
        let mut child = child;
        let status = loop {
            if let Some(st) = child.try_wait().unwrap() {
                break st;
            }
            // A cancel takes milliseconds; minutes means the signal was not handled.
            if t.elapsed() > CASE_LIMIT {
                let _ = child.kill();
                panic!("SIG{sig}: still running {CASE_LIMIT:?} after the signal");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let stderr = child.wait_with_output().map(|o| String::from_utf8_lossy(&o.stderr).into_owned()).unwrap_or_default();
        assert_eq!(status.code(), Some(128 + n), "SIG{sig}: {status:?}: {stderr}");
        assert!(stderr.contains(&format!("SIG{sig}")) && !stderr.contains("panicked"), "SIG{sig}: {stderr}");
        assert!(!out.exists(), "SIG{sig}: no image after a cancelled solve");
        let left: Vec<_> = std::fs::read_dir(&tmp).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert!(left.is_empty(), "SIG{sig}: scratch files left in TMPDIR: {left:?}");
    }
}

/// Outputs that would silently overwrite each other (`--out` and `--out-vdb` the same file,
/// also through another spelling of the path) and an output under a file are refused before
/// anything is solved, naming the flags or the file.
#[test]
fn harden_cli_refuses_clashing_outputs_and_outputs_under_a_file() {
    let dir = scratch_dir("cli-outputs");
    let file = dir.join("afile");
    std::fs::write(&file, "x").unwrap();
    let same = dir.join("s.exr");
    let same_again = dir.join(".").join("s.exr");
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        (vec!["--out".into(), same.clone().into(), "--out-vdb".into(), same_again.clone().into()], "--out and --out-vdb name the same file"),
        (vec!["--out".into(), dir.join("o.exr").into(), "--png".into(), dir.join("r.json").into(), "--report".into(), dir.join("r.json").into()], "--png and --report name the same file"),
        (vec!["--out".into(), file.join("sub").join("o.exr").into()], "is a file, not a folder"),
    ];
    for (args, want) in cases {
        let out = Command::new(cli_binary()).args(["render", "-q", "--solver", "pop", "--device", "cpu"]).args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(want), "{args:?}: {stderr}");
        assert!(!same.exists() && !dir.join("o.exr").exists(), "{args:?}: nothing written");
    }
}
