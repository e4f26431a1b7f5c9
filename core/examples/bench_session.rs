//! Times a session of POP solves against one-off POP solves over the frames of a moving sun on
//! the default scene (plume under sun and sky, POP's default settings), and checks that each
//! session frame is bit-identical to its one-off solve. Prints one JSON object;
//! `scripts/bench_session.py` turns it into the "Sessions" section of BENCHMARKS.md.
//!
//! cargo run --release -p volscatter-core --example bench_session -- [--frames 10] [--repeats 3] [--degrees 4]
//!
//! Each repeat runs, frame by frame, the one-off solve and then the session's solve of the same
//! scene (interleaved, so that load from other processes falls on both alike); a repeat starts
//! a new session. Times are wall-clock; the JSON holds each repeat's totals and per-phase sums.

use serde_json::json;
use std::collections::BTreeMap;
use std::time::Instant;

use volscatter_core::scene::Light;
use volscatter_core::pipeline::{self, Devices, Session};
use volscatter_core::solvers::SolveOutput;
use volscatter_core::stages::NoProgress;
use volscatter_core::Scene;

fn arg(args: &[String], name: &str, default: f64) -> f64 {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The default scene with its sun turned `angle` radians about the vertical.
fn frame(base: &Scene, angle: f32) -> Scene {
    let mut scene = base.clone();
    for l in &mut scene.lights {
        if let Light::Distant { direction, .. } = l {
            *direction = glam::Quat::from_rotation_z(angle) * *direction;
        }
    }
    scene
}

fn add_phases(sum: &mut BTreeMap<String, f64>, out: &SolveOutput) {
    for (k, v) in &out.timings.0 {
        *sum.entry(k.clone()).or_default() += v;
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let frames = arg(&args, "--frames", 10.0) as usize;
    let repeats = arg(&args, "--repeats", 3.0) as usize;
    let step = (arg(&args, "--degrees", 4.0) as f32).to_radians();
    let mut base = Scene::default_scene();
    base.solver = json!({"name": "pop"}).as_object().cloned().unwrap_or_default();
    let settings = base.solver.clone();
    let scenes: Vec<Scene> = (0..frames).map(|f| frame(&base, step * f as f32)).collect();
    let mut runs = Vec::new();
    let mut identical = true;
    for r in 0..repeats {
        let mut session = Session::new("pop", &settings, Devices::cpu()).expect("pop settings");
        let (mut t_one, mut t_sess) = (0.0, 0.0);
        let (mut ph_one, mut ph_sess) = (BTreeMap::new(), BTreeMap::new());
        for scene in &scenes {
            let t = Instant::now();
            let one = pipeline::solve(scene, "pop", &settings, Devices::cpu(), &NoProgress).expect("one-off solve").output;
            t_one += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let kept = session.solve(scene, &NoProgress).expect("session solve").output;
            t_sess += t.elapsed().as_secs_f64();
            identical &= one.scattering.data == kept.scattering.data;
            add_phases(&mut ph_one, &one);
            add_phases(&mut ph_sess, &kept);
        }
        eprintln!("repeat {r}: one-off {t_one:.3} s, session {t_sess:.3} s");
        runs.push(json!({"one_off_seconds": t_one, "session_seconds": t_sess, "one_off_phases": ph_one, "session_phases": ph_sess}));
    }
    let doc = json!({
        "frames": frames,
        "degrees_per_frame": step.to_degrees(),
        "threads": rayon::current_num_threads(),
        "identical": identical,
        "runs": runs,
    });
    println!("{doc}");
}
