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
