//! No solver wildly off (issue 36): every registry entry, `auto` included, on small extreme but
//! legal scenes, through the pipeline as a host runs it (session solve, then the composite of
//! its scattering grid), at its `draft` preset (`auto` at its defaults). Per (solver, case) the
//! solver either refuses the scene with a message naming why and which solver to use, or:
//! - lit scenes: the image's scattered flux (emission seen directly left out) within 2x of the
//!   reference path tracer's image of the same scene;
//! - white furnaces (albedo 1 under a uniform dome of radiance 1): every pixel of the composite
//!   is 1, so the pixels' mean within 10% and no pixel below 0.5 or above 1.5.
//!
//! The table (ratio, or "refused") is printed; with `VS_EXTREMES_WRITE=1` it is also written to
//! BENCHMARKS.md as the section `extremes`.

use glam::{IVec3, Vec3};
use serde_json::{json, Map, Value};

use super::{mean, rgb, scattered};
use crate::compositor::CompositeOptions;
use crate::medium::{DensityGrid, GridLimits, Medium};
use crate::pipeline::{self, Devices, Session};
use crate::scene::{Camera, Environment, Light, Scene};
use crate::solvers::reference::{Reference, ReferenceSettings};
use crate::solvers::registry::{SOLVERS, SOLVER_NAMES};
use crate::solvers::{SolveCtx, Solver};
use crate::stages::{NoProgress, Timings};

/// Image size of every case (small: the table runs every solver on every case).
const W: u32 = 24;
const H: u32 = 18;
/// Paths per pixel of each of the reference image's two halves (seeds 1 and 2); the table
/// asserts their flux noise is under 10%, well inside the 2x bound (at g 0.999 under a sun,
/// 1024 gave 14%: the HG lobe towards a delta sun is a heavy-tailed estimate).
const REFERENCE_SPP: u32 = 4096;
/// Largest ratio of a solver's flux to the reference's, either way (issue 36).
const FLUX_BOUND: f64 = 2.0;
/// A reference flux below this is dark (albedo 0: nothing scatters); a solver passes there when
/// its own flux is dark too.
const DARK: f64 = 1e-6;

/// One extreme scene; `furnace`: a white furnace, checked against its exact image (1).
pub(super) struct Case {
    pub name: &'static str,
    pub scene: Scene,
    pub furnace: bool,
}

/// The small plume (16^3 voxels over about 2 m) under a sun, seen from 6 m, with `edit`
/// applied to its JSON.
fn plume(edit: impl Fn(&mut Value)) -> Scene {
    let mut v = json!({"format": 1,
        "medium": {"procedural": "plume", "dims": [16], "density_scale": 10.0, "albedo": 0.9, "g": 0.5},
        "lights": [{"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 4.0}],
        "camera": {"position": [0, -6, 0.2], "look_at": [0, 0, 0], "width": W, "height": H}});
    edit(&mut v);
    Scene::from_json_str(&v.to_string(), std::path::Path::new(".")).unwrap()
}

/// A box of `n.x` x `n.y` x `n.z` voxels of density 1 and edge `voxel`, centred at the origin.
fn slab(n: IVec3, voxel: f32, density_scale: f32, albedo: f32, g: f32) -> Medium {
    let vals = vec![1.0f32; (n.x * n.y * n.z) as usize];
    let grid = DensityGrid::from_dense(IVec3::ZERO, n, &vals, GridLimits::default()).unwrap();
    let to_world = glam::Affine3A::from_translation(-(n.as_vec3() - Vec3::ONE) * 0.5 * voxel) * glam::Affine3A::from_scale(Vec3::splat(voxel));
    Medium::new(grid, to_world, Vec3::splat(density_scale), Vec3::splat(albedo), g)
}

/// A white furnace: a 1 m box of 8^3 voxels, albedo 1, optical thickness `tau` across, under
/// a dome of radiance 1, filling the middle of the image (background: the dome, also 1).
fn furnace(tau: f32, g: f32) -> Scene {
    Scene {
        medium: slab(IVec3::splat(8), 0.125, tau, 1.0, g),
        lights: vec![Light::Dome(Environment { color: Vec3::ONE, map: None })],
        camera: Camera::look_at(Vec3::new(0.0, -4.0, 0.5), Vec3::ZERO, Vec3::Z, 22.0, W, H),
        solver: Default::default(),
    }
}

pub(super) fn cases() -> Vec<Case> {
    if std::env::var("VS_EXTREMES_EXPLORE").is_ok_and(|v| v == "1") {
        return explore_cases();
    }
    let lit = |name, scene| Case { name, scene, furnace: false };
    let mut thin = plume(|_| {});
    // One voxel thick (0.125 m) and 2 m wide, optical thickness 1 across, lit from above.
    thin.medium = slab(IVec3::new(16, 16, 1), 0.125, 8.0, 0.9, 0.5);
    vec![
        lit("g +0.999", plume(|v| {
            v["medium"]["g"] = json!(0.999);
            v["medium"]["albedo"] = json!(1.0);
        })),
        lit("g -0.999", plume(|v| {
            v["medium"]["g"] = json!(-0.999);
            v["medium"]["albedo"] = json!(1.0);
        })),
        lit("albedo 0", plume(|v| v["medium"]["albedo"] = json!(0.0))),
        lit("albedo 1", plume(|v| v["medium"]["albedo"] = json!(1.0))),
        lit("density x1e4", plume(|v| v["medium"]["density_scale"] = json!(1e4))),
        lit("camera inside", plume(|v| {
            v["camera"]["position"] = json!([0.01, 0.02, 0.03]);
            v["camera"]["look_at"] = json!([0.0, 1.0, 0.1]);
        })),
        lit("light inside", plume(|v| v["lights"] = json!([{"type": "point", "position": [0.05, 0.0, 0.1], "intensity": 4.0}]))),
        lit("emission only", plume(|v| {
            v["lights"] = json!([]);
            v["medium"]["emission"] = json!({"grid": "density", "strength": 1.0});
        })),
        lit("one voxel thin", thin),
        Case { name: "furnace g 0", scene: furnace(4.0, 0.0), furnace: true },
        Case { name: "furnace g +0.999", scene: furnace(4.0, 0.999), furnace: true },
        Case { name: "furnace g -0.999", scene: furnace(4.0, -0.999), furnace: true },
        Case { name: "furnace dense", scene: furnace(100.0, 0.5), furnace: true },
    ]
}

/// The limits' neighbourhood (`VS_EXTREMES_EXPLORE=1`): where each solver starts to be off,
/// to set its refusals (limits.rs) no wider than the measurements show.
fn explore_cases() -> Vec<Case> {
    let mut out = Vec::new();
    for g in [0.9f32, 0.95, 0.98, 0.99, -0.9, -0.95, -0.98, -0.99] {
        let name: &'static str = Box::leak(format!("g {g:+}").into_boxed_str());
        out.push(Case { name, scene: plume(|v| { v["medium"]["g"] = json!(g); v["medium"]["albedo"] = json!(1.0); }), furnace: false });
        let name: &'static str = Box::leak(format!("furnace g {g:+}").into_boxed_str());
        out.push(Case { name, scene: furnace(4.0, g), furnace: true });
    }
    for scale in [30.0f32, 100.0, 300.0, 1000.0] {
        let name: &'static str = Box::leak(format!("density x{scale}").into_boxed_str());
        out.push(Case { name, scene: plume(|v| v["medium"]["density_scale"] = json!(scale)), furnace: false });
    }
    for tau in [10.0f32, 20.0, 40.0] {
        let name: &'static str = Box::leak(format!("furnace tau {tau}").into_boxed_str());
        out.push(Case { name, scene: furnace(tau, 0.5), furnace: true });
    }
    out.push(Case { name: "camera inside g 0", scene: plume(|v| {
        v["camera"]["position"] = json!([0.01, 0.02, 0.03]);
        v["camera"]["look_at"] = json!([0.0, 1.0, 0.1]);
        v["medium"]["g"] = json!(0.0);
    }), furnace: false });
    out.push(Case { name: "camera inside x0.2", scene: plume(|v| {
        v["camera"]["position"] = json!([0.01, 0.02, 0.03]);
        v["camera"]["look_at"] = json!([0.0, 1.0, 0.1]);
        v["medium"]["density_scale"] = json!(2.0);
    }), furnace: false });
    out
}

/// The reference path tracer's image of `sc` (transparent, scattered light only).
fn reference_flux(sc: &Scene, seed: u64) -> f64 {
    let r = Reference::new(ReferenceSettings { spp: REFERENCE_SPP, seed, transparent: true, ..Default::default() }).unwrap();
    let img = r.render_image(sc, &mut SolveCtx::new(&NoProgress), true, &mut Timings::default()).expect("the reference renders images").unwrap();
    mean(&scattered(&img))
}

/// What one solver did on one case.
pub(super) enum Outcome {
    /// Flux ratio to the reference (lit), or mean pixel with its darkest and brightest (furnace).
    Flux(f64),
    Furnace { mean: f64, min: f64, max: f64 },
    Refused(String),
    /// Failed without naming a solver to use instead: a failure of the table.
    Failed(String),
}

impl Outcome {
    fn passes(&self, ref_dark: bool) -> bool {
        match self {
            Outcome::Flux(r) if ref_dark => *r < DARK,
            Outcome::Flux(r) => (1.0 / FLUX_BOUND..=FLUX_BOUND).contains(r),
            Outcome::Furnace { mean, min, max } => (mean - 1.0).abs() <= 0.1 && *min >= 0.5 && *max <= 1.5,
            Outcome::Refused(_) => true,
            Outcome::Failed(_) => false,
        }
    }
    fn cell(&self, ref_dark: bool) -> String {
        let mark = if self.passes(ref_dark) { "" } else { " **X**" };
        match self {
            Outcome::Flux(r) if ref_dark => format!("{r:.1e}{mark}"),
            Outcome::Flux(r) => format!("{r:.2}{mark}"),
            Outcome::Furnace { mean, min, max } => format!("{mean:.2} [{min:.2}, {max:.2}]{mark}"),
            Outcome::Refused(_) => "refused".into(),
            Outcome::Failed(_) => format!("error{mark}"),
        }
    }
}

/// The settings a solver runs at here: its `draft` preset; `auto` at its defaults. The path
/// tracer's grid at its default 256 paths per point: at draft's 16 its noise alone puts pixels
/// of a dense furnace beyond 2x (measured [0.09, 3.20]), and the table is about bias.
fn settings(name: &str) -> Map<String, Value> {
    let entry = crate::solvers::registry::get(name).unwrap();
    let mut s = entry.preset("draft").map(|p| p.settings()).unwrap_or_default();
    if name == "reference" {
        s.insert("grid_spp".into(), json!(256));
    }
    s
}

/// Whether an error message is a refusal: it says which registry solver to use (the path
/// tracer's grid names its own image).
fn names_a_solver(msg: &str) -> bool {
    msg.contains("refuses this scene") && msg.split("; use ").nth(1).is_some_and(|rest| SOLVER_NAMES.iter().any(|s| *s != "auto" && rest.contains(s)))
}

/// (solver, case, reason) outside the bounds that the table reports but does not fail on;
/// none may be over 2x. Empty since auto's refit (before it, auto's photon-grid final was 11%
/// dark in the dense furnace).
const KNOWN: &[(&str, &str, &str)] = &[];

fn known(name: &str, case: &str) -> Option<&'static str> {
    KNOWN.iter().find(|k| k.0 == name && k.1 == case).map(|k| k.2)
}

/// Runs solver `name` on `case` as a host does: a session's solve, then the composite of its
/// grid (transparent for lit cases, over the dome for furnaces). Returns the outcome, its
/// flux (lit) and seconds.
pub(super) fn run(name: &str, case: &Case) -> (Outcome, f64, f64) {
    let t = std::time::Instant::now();
    let solved = Session::new(name, &settings(name), Devices::cpu()).and_then(|mut s| s.solve(&case.scene, &NoProgress));
    let out = match solved {
        Err(e) => {
            let msg = e.to_string();
            let o = if names_a_solver(&msg) { Outcome::Refused(msg) } else { Outcome::Failed(msg) };
            return (o, 0.0, t.elapsed().as_secs_f64());
        }
        Ok(s) => s,
    };
    let secs = t.elapsed().as_secs_f64();
    let opts = CompositeOptions { transparent: !case.furnace, ..Default::default() };
    let img = pipeline::composite(&case.scene, &out.output.scattering, &opts, Devices::cpu()).unwrap().image;
    if case.furnace {
        let px: Vec<f64> = rgb(&img).iter().map(|p| (p.x + p.y + p.z) as f64 / 3.0).collect();
        let m = px.iter().sum::<f64>() / px.len() as f64;
        let (lo, hi) = px.iter().fold((f64::MAX, f64::MIN), |(a, b), &p| (a.min(p), b.max(p)));
        (Outcome::Furnace { mean: m, min: lo, max: hi }, m, secs)
    } else {
        let f = mean(&scattered(&img));
        (Outcome::Flux(f), f, secs)
    }
}

/// The whole table; returns its markdown lines and the failures.
fn table() -> (Vec<String>, Vec<String>) {
    let cases = cases();
    let names: Vec<&str> = SOLVERS.iter().map(|e| e.name).collect();
    let mut header = "| solver |".to_string();
    for c in &cases {
        header += &format!(" {} |", c.name);
    }
    let mut lines = vec![header, format!("|---|{}", "---|".repeat(cases.len()))];
    let mut failures = Vec::new();
    let mut refusals = Vec::new();
    let mut notes = Vec::new();
    let refs: Vec<Option<f64>> = cases
        .iter()
        .map(|c| {
            (!c.furnace).then(|| {
                let (a, b) = (reference_flux(&c.scene, 1), reference_flux(&c.scene, 2));
                let f = 0.5 * (a + b);
                // Half the relative difference of two independent halves: the mean's noise.
                let noise = if f > DARK { 0.5 * (a - b).abs() / f } else { 0.0 };
                eprintln!("reference {}: flux {f:.4e} (noise {noise:.3})", c.name);
                let exploring = std::env::var("VS_EXTREMES_EXPLORE").is_ok_and(|v| v == "1");
                assert!(exploring || noise < 0.1, "{}: the reference's flux noise {noise} is not well under the 2x bound", c.name);
                f
            })
        })
        .collect();
    let mut slowest = Vec::new();
    for name in &names {
        let mut row = format!("| {name} |");
        for (c, r) in cases.iter().zip(&refs) {
            let (mut o, flux, secs) = run(name, c);
            let dark = r.is_some_and(|r| r < DARK);
            if let (Outcome::Flux(_), Some(r)) = (&o, r) {
                o = Outcome::Flux(if dark { flux } else { flux / r });
            }
            eprintln!("{name} on {}: {} ({secs:.2} s)", c.name, o.cell(dark));
            slowest.push((secs, format!("{name} on {}", c.name)));
            match &o {
                Outcome::Refused(m) => refusals.push(format!("{name} on {}: {m}", c.name)),
                Outcome::Failed(m) => failures.push(format!("{name} on {}: failed without naming a solver to use: {m}", c.name)),
                o if !o.passes(dark) => match known(name, c.name) {
                    Some(why) => notes.push(format!("{name} on {}: {} ({why})", c.name, o.cell(dark))),
                    None => failures.push(format!("{name} on {}: {}", c.name, o.cell(dark))),
                },
                _ => {}
            }
            row += &format!(" {} |", o.cell(dark));
        }
        lines.push(row);
    }
    slowest.sort_by(|a, b| b.0.total_cmp(&a.0));
    lines.push(String::new());
    lines.push(format!(
        "Lit cases: flux of the composite of the solver's scattering grid over the reference path tracer's image (2 x {REFERENCE_SPP} spp), bound {FLUX_BOUND}x either way (albedo 0: the solver's flux, dark below {DARK:e}). Furnaces: mean pixel [darkest, brightest], exact 1, bound 10% on the mean and [0.5, 1.5] per pixel. **X**: outside the bound. Slowest solves: {}.",
        slowest.iter().take(3).map(|(s, n)| format!("{n} {s:.1} s")).collect::<Vec<_>>().join(", ")
    ));
    if !notes.is_empty() {
        lines.push(String::new());
        lines.push("Outside the bounds, within 2x, known:".into());
        lines.extend(notes.iter().map(|r| format!("- {r}")));
    }
    if !refusals.is_empty() {
        lines.push(String::new());
        lines.push("Refusals:".into());
        lines.extend(refusals.iter().map(|r| format!("- {r}")));
    }
    (lines, failures)
}

/// Today's date (UTC) as YYYY-MM-DD, from the days since 1970 (the civil-from-days
/// conversion of H. Hinnant's date algorithms; no date crate for one line of a table).
fn utc_date() -> String {
    let days = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 86_400) as i64;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// Writes `body` between the `extremes` markers of BENCHMARKS.md (appended when absent), as
/// scripts/benchlib.py's `write_section` does, through a temporary file renamed over it.
fn publish(body: &str) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../BENCHMARKS.md");
    let text = std::fs::read_to_string(&path).unwrap_or_default();
    let (begin, end) = ("<!-- BEGIN extremes -->", "<!-- END extremes -->");
    let section = format!("{begin}\n{body}\n{end}");
    let out = match (text.find(begin), text.find(end)) {
        (Some(a), Some(b)) if b > a => format!("{}{section}{}", &text[..a], &text[b + end.len()..]),
        _ => format!("{}\n\n{section}\n", text.trim_end()),
    };
    let tmp = path.with_extension("md.tmp");
    std::fs::write(&tmp, out).unwrap();
    std::fs::rename(&tmp, &path).unwrap();
}

#[test]
fn no_solver_wildly_off_on_extreme_scenes() {
    let t = std::time::Instant::now();
    let (lines, failures) = table();
    let body = format!(
        "## No solver wildly off (issue 36; `core/src/solvers/testing/extremes.rs`)\n\nEvery registry entry at its `draft` preset (`auto` at its defaults), {W}x{H} pixels, media of 16^3 voxels or fewer, CPU; the table of the test `no_solver_wildly_off_on_extreme_scenes` (written here with `VS_EXTREMES_WRITE=1`).\n\n{}",
        lines.join("\n")
    );
    println!("{body}");
    eprintln!("extremes table: {:.0} s", t.elapsed().as_secs_f64());
    if std::env::var("VS_EXTREMES_WRITE").is_ok_and(|v| v == "1") {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let stamp = format!(
            "Written on {} ({threads} threads, {}) by `VS_EXTREMES_WRITE=1 cargo nextest run -p volscatter-core --cargo-profile release -E 'test(no_solver_wildly_off_on_extreme_scenes)'`.",
            utc_date(),
            std::env::consts::ARCH
        );
        publish(&body.replacen("\n\n", &format!("\n\n{stamp} "), 1));
    }
    assert!(failures.is_empty(), "solvers wildly off without refusing:\n{}", failures.join("\n"));
}

/// The limits are tight enough to refuse none of the ordinary scenes every solver is measured
/// on (the converged fixtures: plume, cubes, cloud, local lights, domes).
#[test]
fn no_solver_refuses_the_fixture_scenes() {
    let mut refused = Vec::new();
    for fixture in super::fixture_names() {
        let sc = super::fixture_scene(fixture);
        for name in SOLVER_NAMES {
            if let Err(e) = crate::solvers::limits::check_scene(name, &sc) {
                refused.push(format!("{fixture}: {e}"));
            }
        }
    }
    assert!(refused.is_empty(), "ordinary scenes refused:\n{}", refused.join("\n"));
}

/// `auto` never picks a solver that refuses the scene: on every extreme case its pick passes
/// the solver's scene check (the session would refuse it otherwise).
#[test]
fn auto_never_picks_a_refusing_solver() {
    for case in cases() {
        let choice = crate::pipeline::auto::choose(&case.scene, &Map::new(), crate::solvers::registry::preset_settings).unwrap();
        let check = crate::solvers::limits::check_scene(&choice.solver, &case.scene);
        eprintln!("{}: auto picks {} {} ({})", case.name, choice.solver, choice.quality, choice.why);
        // Where every solver's grid refuses, auto's fall-back is the path tracer, whose image
        // is right (and whose grid's refusal says so).
        let all_refuse = SOLVER_NAMES.iter().filter(|n| **n != "auto").all(|n| crate::solvers::limits::check_scene(n, &case.scene).is_err());
        assert!(check.is_ok() || (all_refuse && choice.solver == "reference"), "{}: auto picked {}, which refuses it: {}", case.name, choice.solver, check.unwrap_err());
    }
    // And some solver does refuse g 0.999, so the check above is not empty.
    let g = &cases()[0];
    assert!(SOLVER_NAMES.iter().any(|n| crate::solvers::limits::check_scene(n, &g.scene).is_err()), "nothing refuses {}", g.name);
}
