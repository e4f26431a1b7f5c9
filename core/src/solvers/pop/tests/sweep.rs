//! Exploration tool (issue 15): POP's errors on the dense cloud (defaults) and on the ratchet
//! cases (at the ratchet's `test_settings`), for the settings in `POP_SET`
//! (`key=value,key=value`, JSON values). Prints, asserts nothing: `cargo nextest run
//! --cargo-profile release -p volscatter-core pop_sweep --run-ignored only --no-capture`.

use crate::solvers::SolveCtx;
use super::{pop_vs_fixture, test_settings, CASES};
use crate::solvers::pop::{Pop, PopSettings};
use crate::solvers::testing::cloud::cloud_scene;
use crate::solvers::testing::errors_against_fixture;
use crate::solvers::{Solver};
use crate::stages::NoProgress;

pub(super) fn with_env(base: PopSettings) -> PopSettings {
    let mut v = serde_json::to_value(base).unwrap();
    for kv in std::env::var("POP_SET").unwrap_or_default().split(',').filter(|s| !s.is_empty()) {
        let (k, val) = kv.split_once('=').expect("POP_SET: key=value");
        v[k] = serde_json::from_str(val).unwrap_or(serde_json::Value::String(val.into()));
    }
    serde_json::from_value(v).unwrap()
}

#[test]
#[ignore]
fn pop_sweep() {
    let sc = cloud_scene();
    let s = with_env(PopSettings::default());
    let t = std::time::Instant::now();
    let out = Pop::new(s).unwrap().solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap();
    let e = errors_against_fixture("cloud", &sc, &out.scattering);
    eprintln!("cloud     image {:.3} (x{:.3}) grid {:.3} (x{:.3}) {:.2}s", e.image, e.image_ratio, e.grid, e.grid_ratio, t.elapsed().as_secs_f64());
    if std::env::var("POP_MAP").is_ok() {
        let fx = crate::solvers::testing::load_fixture("cloud");
        let pop = crate::solvers::testing::SolverOutput::of(&sc, &out.scattering);
        let r = fx.image();
        let n = crate::solvers::testing::cloud::CLOUD_SIZE as usize;
        let max = r.iter().map(|p| p.x).fold(0.0f32, f32::max);
        eprintln!("reference (tenths of max) | POP / reference (x5, '.' where the reference < 2% of max)");
        for y in 0..n {
            let a: String = (0..n).map(|x| char::from(b'0' + ((r[y * n + x].x / max) * 9.0).round() as u8)).collect();
            let b: String = (0..n)
                .map(|x| {
                    let (p, q) = (pop.image[y * n + x].x, r[y * n + x].x);
                    if q < 0.02 * max { '.' } else { char::from(b'0' + ((p / q) * 5.0).round().min(9.0) as u8) }
                })
                .collect();
            eprintln!("{a} | {b}");
        }
    }
    if std::env::var("POP_ONLY_CLOUD").is_ok() {
        return;
    }
    for name in CASES {
        let (e, _) = pop_vs_fixture(name, &with_env(test_settings()));
        eprintln!("{name:9} image {:.3} (x{:.3}) grid {:.3} (x{:.3})", e.image, e.image_ratio, e.grid, e.grid_ratio);
    }
}
