//! The extreme-value scenes of `volscatter_tests::extreme` through the C ABI, and the C ABI's
//! progress contract (issue 22): the callback is called at least every 100 ms during every
//! solve and render, and a cancel ends a long solve quickly with VS_STATUS_CANCELLED.

use std::ffi::{c_char, c_void};
use std::ptr::null_mut;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use volscatter_tests::cdylib::{cdylib, scratch_dir};
use volscatter_tests::extreme::{cases, TEST_BUDGET};
use volscatter_tests::vsapi::{cstr, status::*, Api, Img, Res, Scene};

fn api() -> &'static Api {
    static API: OnceLock<Api> = OnceLock::new();
    API.get_or_init(|| {
        let api = Api::load(cdylib()).unwrap_or_else(|e| panic!("loading {}: {e}", cdylib().display()));
        // Over-budget cases must be refused on any machine, whatever its memory.
        assert_eq!(unsafe { (api.vs_set_memory_budget)(TEST_BUDGET) }, OK);
        assert_eq!(unsafe { (api.vs_memory_budget)() }, TEST_BUDGET);
        api
    })
}

/// Seconds any one case may take: each is a small scene that ends well under a second on
/// one core when it runs, or is refused at once. 20 s is 20x that, for a loaded CI machine;
/// a hang (what this catches) never ends.
const CASE_LIMIT: Duration = Duration::from_secs(20);

/// Every case ends in OK with a finite grid, or an error other than INTERNAL whose message is
/// not empty; none takes longer than CASE_LIMIT. The cases the issue names as wrong answers or
/// hangs must be the error, not OK.
#[test]
fn extreme_scenes_end_in_ok_and_finite_or_a_clear_error() {
    let a = api();
    let dir = scratch_dir("extreme-abi");
    let dir_c = cstr(dir.to_str().unwrap());
    let mut report = Vec::new();
    for (name, scene) in cases(&dir) {
        eprintln!("case {name}");
        let s: Scene = a.new_scene();
        let t = Instant::now();
        let st = unsafe { (a.vs_scene_load_json)(s, cstr(&scene.to_string()).as_ptr(), dir_c.as_ptr()) };
        let (st, msg) = if st != OK {
            (st, a.scene_error(s))
        } else {
            let mut r: Res = null_mut();
            let st = unsafe { (a.vs_scene_solve)(s, None, null_mut(), &mut r) };
            if st != OK {
                (st, a.scene_error(s))
            } else {
                let (_, data) = a.grid(r);
                assert!(data.iter().all(|v| v.is_finite()), "{name}: status OK with non-finite values in the grid");
                if name.starts_with("no lights") {
                    assert!(data.iter().all(|v| *v == 0.0), "{name}: no light, yet a lit grid");
                }
                // And its composite: OK and finite, or an error on the result.
                let mut img: Img = null_mut();
                let st = unsafe { (a.vs_result_composite)(r, 0, 1, 0.5, &mut img) };
                let msg = a.result_error(r);
                if st == OK {
                    let (mut w, mut h) = (0u32, 0u32);
                    assert_eq!(unsafe { (a.vs_image_size)(img, &mut w, &mut h) }, OK);
                    let mut rgba = vec![0f32; 4 * w as usize * h as usize];
                    assert_eq!(unsafe { (a.vs_image_copy_rgba)(img, rgba.as_mut_ptr(), rgba.len()) }, OK);
                    assert!(rgba.iter().all(|v| v.is_finite()), "{name}: composite OK with non-finite pixels");
                    unsafe { (a.vs_image_destroy)(img) };
                }
                unsafe { (a.vs_result_destroy)(r) };
                (st, msg)
            }
        };
        let took = t.elapsed();
        unsafe { (a.vs_scene_destroy)(s) };
        assert!(took < CASE_LIMIT, "{name}: took {took:?}");
        assert_ne!(st, INTERNAL, "{name}: internal error {msg}");
        if st != OK {
            assert!(!msg.is_empty(), "{name}: status {st} without a message");
        }
        let must_fail = ["1e8", "3e38", "1e30", "1e-45", "radius 1e-30", "over the budget"];
        if must_fail.iter().any(|w| name.contains(w)) && !name.contains("empty") && !name.contains("dome colour 1e30") {
            assert_ne!(st, OK, "{name}: must be refused");
        }
        // Every solver returns black for a scene without lights (pop refused it before issue 40).
        if name.starts_with("no lights") {
            assert_eq!(st, OK, "{name}: {msg}");
        }
        if name.contains("over the budget") {
            assert_eq!(st, TOO_LARGE, "{name}: {msg}");
            assert!(msg.contains("budget") && msg.contains("1.0 GiB"), "{name}: the refusal names the budget: {msg}");
        }
        report.push(format!("{name}: status {st} in {:.2} s: {msg}", took.as_secs_f64()));
    }
    eprintln!("{}", report.join("\n"));
    assert!(report.len() >= 30, "{} cases", report.len());
}

/// What a progress callback saw: when it was called, and when to start cancelling.
struct Beats {
    start: Instant,
    calls: Vec<Instant>,
    cancel_after: Duration,
    /// The process's CPU time when the callback first asked to stop.
    cpu_at_cancel: Option<Duration>,
}

unsafe extern "C" fn record(user: *mut c_void, _stage: *const c_char, _fraction: f32) -> i32 {
    let beats = &mut *(user as *mut Beats);
    let now = Instant::now();
    beats.calls.push(now);
    let go_on = now - beats.start < beats.cancel_after;
    if !go_on && beats.cpu_at_cancel.is_none() {
        beats.cpu_at_cancel = process_cpu();
    }
    i32::from(go_on)
}

/// CPU time (user + system) of this process, all threads, from /proc (Linux; None elsewhere).
fn process_cpu() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) in parentheses: utime and stime
    // are the 12th and 13th, in clock ticks of 1/100 s on Linux (USER_HZ).
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<u64> = rest.split_whitespace().skip(11).take(2).map(|v| v.parse().ok()).collect::<Option<_>>()?;
    Some(Duration::from_millis(10 * (f.first()? + f.get(1)?)))
}

/// How a call ended after a cancel: its status, the largest gap between the start, the
/// callbacks and the return, the wall-clock time from the cancel to the return, and the CPU
/// time all threads spent in it (None where it cannot be read).
struct Ended {
    status: i32,
    gap: Duration,
    cancel: Duration,
    cpu_after_cancel: Option<Duration>,
}

/// Runs `call` with the recording callback (cancelling after `cancel_after`).
fn run_ended(cancel_after: Duration, call: impl FnOnce(*mut c_void) -> i32) -> Ended {
    let mut beats = Beats { start: Instant::now(), calls: Vec::new(), cancel_after, cpu_at_cancel: None };
    let status = call(&mut beats as *mut Beats as *mut c_void);
    let end = Instant::now();
    let cpu_after_cancel = beats.cpu_at_cancel.zip(process_cpu()).map(|(a, b)| b.saturating_sub(a));
    let mut times = vec![beats.start];
    times.extend(&beats.calls);
    times.push(end);
    let gap = times.windows(2).map(|w| w[1] - w[0]).max().unwrap_or_default();
    let cancel = end.saturating_duration_since(beats.start + cancel_after);
    eprintln!("{} callbacks, longest silence {gap:?}, cancel to return {cancel:?}, CPU after the cancel {cpu_after_cancel:?}", beats.calls.len());
    Ended { status, gap, cancel, cpu_after_cancel }
}

/// `run_ended`'s status, longest silence and cancel-to-return time.
fn run_with_beats(cancel_after: Duration, call: impl FnOnce(*mut c_void) -> i32) -> (i32, Duration, Duration) {
    let e = run_ended(cancel_after, call);
    (e.status, e.gap, e.cancel)
}

/// A scene whose reference solve and render take minutes (2^20 paths per pixel and per grid
/// point) unless cancelled.
fn long_scene() -> Scene {
    api().scene_from_json(
        r#"{"format": 1, "medium": {"procedural": "plume", "dims": [16], "density_scale": 10.0, "albedo": 0.9},
            "lights": [{"type": "distant", "direction": [0, 0, -1], "irradiance": 1.0}],
            "camera": {"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12},
            "solver": {"name": "reference", "spp": 1048576, "grid_resolution": 8, "grid_spp": 1048576}}"#,
    )
}

/// Longest a cancel may take to end the call: the reference reads the flag every 16 paths
/// (each well under a millisecond here), the heartbeat calls the host every 100 ms. 2 s is
/// slack for a loaded machine; without the fix the call never returned.
const CANCEL_LIMIT: Duration = Duration::from_secs(2);
/// Longest silence allowed between callbacks: the heartbeat aims at 100 ms; 3x for a loaded
/// two-core CI machine (measured here: about 100 ms).
const GAP_LIMIT: Duration = Duration::from_millis(300);

#[test]
fn render_reference_reports_every_100ms_and_cancels_quickly() {
    let a = api();
    let s = long_scene();
    let mut img: Img = null_mut();
    let (st, gap, cancel) = run_with_beats(Duration::from_millis(800), |user| unsafe { (a.vs_scene_render_reference)(s, Some(record), user, &mut img) });
    assert_eq!(st, CANCELLED, "{}", a.scene_error(s));
    assert!(img.is_null());
    assert!(gap < GAP_LIMIT, "longest silence {gap:?}");
    assert!(cancel < CANCEL_LIMIT, "cancel took {cancel:?}");
    unsafe { (a.vs_scene_destroy)(s) };
}

#[test]
fn solve_reports_every_100ms_and_cancels_quickly() {
    let a = api();
    let s = long_scene();
    let mut r: Res = null_mut();
    let (st, gap, cancel) = run_with_beats(Duration::from_millis(800), |user| unsafe { (a.vs_scene_solve)(s, Some(record), user, &mut r) });
    assert_eq!(st, CANCELLED, "{}", a.scene_error(s));
    assert!(r.is_null());
    assert!(gap < GAP_LIMIT, "longest silence {gap:?}");
    assert!(cancel < CANCEL_LIMIT, "cancel took {cancel:?}");
    // A session solve of the same scene: the same contract.
    let mut sess = null_mut();
    assert_eq!(unsafe { (a.vs_session_new)(s, &mut sess) }, OK);
    let (st, gap, cancel) = run_with_beats(Duration::from_millis(500), |user| unsafe { (a.vs_session_solve)(sess, s, Some(record), user, &mut r) });
    assert_eq!(st, CANCELLED, "{}", a.session_error(sess));
    assert!(gap < GAP_LIMIT && cancel < CANCEL_LIMIT, "session: silence {gap:?}, cancel {cancel:?}");
    unsafe { (a.vs_session_destroy)(sess) };
    unsafe { (a.vs_scene_destroy)(s) };
}

/// Settings that keep each registered solver busy for many seconds (minutes for most) on this
/// scene, so that a cancel after 50 ms lands inside its long loops, not after it finished.
/// A solver added to the registry must be added here (the test fails naming it otherwise).
fn heavy_settings(name: &str) -> &'static str {
    match name {
        "reference" => r#"{"spp": 1048576, "grid_resolution": 16, "grid_spp": 1048576}"#,
        "pop" => r#"{"grid_resolution": 96, "max_iterations": 100000, "residual_threshold": 0, "output_resolution": 256}"#,
        "vpl" => r#"{"walks": 16777216, "gather_resolution": 64, "output_resolution": 256}"#,
        "photon-grid" => r#"{"photons": 1073741824, "cache_resolution": 128, "output_resolution": 256}"#,
        "network" => r#"{"particles": 8192, "directions": 1024, "max_iterations": 100000, "residual_threshold": 0, "output_resolution": 256}"#,
        "lpm" => r#"{"grid_resolution": 128, "max_orders": 100000, "epsilon": 1e-9, "output_resolution": 256}"#,
        // An unreachable target: the most accurate measured configuration runs (a final preset,
        // seconds or more on this scene); the cancel reaches it through the same callback.
        "auto" => r#"{"time_budget": 1e9}"#,
        other => panic!("solver {other:?} has no heavy settings in this test: add them"),
    }
}

/// The work a solve may do after a cancel, in CPU time per worker thread: the solvers read
/// the flag at a stride of about 10 ms of work on one core (issue 22 asks for 100 ms), and the
/// worker that reads it last stops within one stride; freeing the solver's buffers adds a
/// little. CPU time, unlike the wall clock, does not grow when other processes load the
/// machine (a worker waiting for a core spends none), so the bound holds on a loaded CI
/// machine; 100 ms is 10x the stride. Before issue 40, pop spent 0.4 s of it in its dome
/// importance and photon-grid 0.4-0.8 s summing batch caches after a cancel; pop later spent
/// up to 0.57 s (CI) in its first light grid, sweep and propagation step, and vpl up to 0.17 s
/// freeing per-walk lists.
const CANCEL_CPU_PER_WORKER: Duration = Duration::from_millis(100);

/// A wall-clock bound that only a hang (a loop that never reads the flag) exceeds, even on a
/// machine loaded many times over.
const CANCEL_HANG_LIMIT: Duration = Duration::from_secs(10);

/// Rayon's worker threads in this process (RAYON_NUM_THREADS, else one per core).
fn workers() -> u32 {
    std::env::var("RAYON_NUM_THREADS").ok().and_then(|v| v.parse().ok()).filter(|n| *n > 0).unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get() as u32))
}

/// When the callback cancels: early (set-up, first walks or photons), later (propagation,
/// gather, iterations) and later still (lpm's and network's first order, after seconds of
/// buffer set-up and visibility on a loaded CI machine), so that more than one stage of each
/// solver is hit. CI once caught lpm's first sweep ignoring a cancel for 12 s at 400 ms.
const CANCEL_POINTS: [Duration; 3] = [Duration::from_millis(50), Duration::from_millis(400), Duration::from_millis(1500)];

/// Every registered solver, started with settings that take seconds to minutes and cancelled
/// from the callback after 50 ms, 400 ms and 1.5 s (one solve each), returns VS_STATUS_CANCELLED
/// with no result, having spent at most CANCEL_CPU_PER_WORKER of CPU per worker after the
/// cancel (where the CPU time can be read; else the wall clock, 500 ms).
#[test]
fn every_solver_cancels_within_500ms() {
    let a = api();
    let mut failures = Vec::new();
    let t0 = Instant::now();
    for &name in volscatter_core::solvers::registry::SOLVER_NAMES {
        let scene = format!(
            r#"{{"format": 1, "medium": {{"procedural": "plume", "dims": [48], "density_scale": 10.0, "albedo": 0.9}},
                "lights": [{{"type": "distant", "direction": [0, 0, -1], "irradiance": 1.0}},
                           {{"type": "point", "position": [0.3, 0.2, 1.5], "intensity": 1.0}},
                           {{"type": "dome", "color": [0.2, 0.3, 0.4]}}],
                "camera": {{"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": 16, "height": 12}},
                "solver": {{"name": "{name}"}}}}"#
        );
        let s = a.scene_from_json(&scene);
        let settings = cstr(heavy_settings(name));
        assert_eq!(unsafe { (a.vs_scene_set_solver)(s, cstr(name).as_ptr(), settings.as_ptr()) }, OK, "{name}: {}", a.scene_error(s));
        // `auto` runs a measured configuration it predicts for this scene, which may end within
        // 400 ms: it is cancelled early (during its pick and the chosen solver's set-up); the
        // solver it hands over to is cancelled at every point under its own name.
        let points = if name == "auto" { &CANCEL_POINTS[..1] } else { &CANCEL_POINTS[..] };
        for &after in points {
            let mut r: Res = null_mut();
            eprintln!("solver {name}, cancel after {after:?} (test at {:?})", t0.elapsed());
            let e = run_ended(after, |user| unsafe { (a.vs_scene_solve)(s, Some(record), user, &mut r) });
            let slow = match e.cpu_after_cancel {
                Some(cpu) => cpu > CANCEL_CPU_PER_WORKER * workers() || e.cancel >= CANCEL_HANG_LIMIT,
                None => e.cancel >= Duration::from_millis(500),
            };
            if e.status != CANCELLED || !r.is_null() || slow {
                failures.push(format!(
                    "{name} cancelled after {after:?}: status {} ({}), cancel took {:?} and {:?} of CPU ({} workers), longest silence {:?}",
                    e.status,
                    a.scene_error(s),
                    e.cancel,
                    e.cpu_after_cancel,
                    workers(),
                    e.gap
                ));
            }
            if !r.is_null() {
                unsafe { (a.vs_result_destroy)(r) };
            }
        }
        unsafe { (a.vs_scene_destroy)(s) };
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
