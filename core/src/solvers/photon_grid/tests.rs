//! photon-grid: physical checks and errors against the shared reference fixtures.

use glam::Vec3;

use super::*;
use crate::compositor::{CompositeOptions};
use crate::stages::single_scattering::{dome_directions_for, single_scattering_grid};
use crate::solvers::testing::{against_reference, against_single_scattering, env_u32, errors_against_fixture, Errors};
use crate::stages::NoProgress;

/// The fixtures' scenes (testing/scenes.rs, the dense cloud testing/cloud.rs).
pub(super) use crate::solvers::testing::fixture_scene as case;

fn solve(sc: &Scene, s: PhotonGridSettings) -> (SolveOutput, PhotonGridReport) {
    PhotonGrid::new(s).unwrap().solve(sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap()
}

fn against(name: &str, s: PhotonGridSettings) -> (Errors, PhotonGridReport, f64) {
    let sc = case(name);
    let t = std::time::Instant::now();
    let (out, rep) = solve(&sc, s);
    let secs = t.elapsed().as_secs_f64();
    (errors_against_fixture(name, &sc, &out.scattering), rep, secs)
}

fn print(name: &str, what: &str, e: &Errors, rep: &PhotonGridReport, secs: f64) {
    eprintln!("{name} [{what}]: {e}; {}; {secs:.2} s", energy(rep));
}

/// Where the photons' power went, and their scatterings and switches per photon.
fn energy(rep: &PhotonGridReport) -> String {
    let en = &rep.energy;
    let lost = |v: glam::DVec3| v.element_sum() / en.emitted.element_sum().max(1e-30);
    format!(
        "escaped {:.4} absorbed {:.4} cut {:.5}, {:.1} scatterings/photon, {:.3} switched",
        lost(en.escaped),
        lost(en.absorbed),
        lost(en.cut),
        en.scatterings as f64 / en.photons.max(1) as f64,
        en.switched as f64 / en.photons.max(1) as f64,
    )
}

/// Prints errors for settings variants (PG_CASE selects cases, PG_PHOTONS the photon count).
#[test]
#[ignore]
fn explore() {
    let photons = env_u32("PG_PHOTONS", 1 << 18);
    let cache_resolution = env_u32("PG_CACHE", 24);
    let output_resolution = env_u32("PG_OUTPUT", 64);
    let only = std::env::var("PG_CASE").unwrap_or_default();
    for name in ["cube_g0", "cube_g07", "cube_g09", "plume", "cloud"] {
        if !only.is_empty() && !name.contains(only.as_str()) {
            continue;
        }
        for (what, s) in [
            ("exact sqrt", PhotonGridSettings { photons, cache_resolution, output_resolution, ..Default::default() }),
            ("photons sqrt", PhotonGridSettings { photons, cache_resolution, output_resolution, single_scattering: SingleScattering::Photons, ..Default::default() }),
            ("exact linear", PhotonGridSettings { photons, cache_resolution, output_resolution, similarity: Similarity::Linear, ..Default::default() }),
            ("exact off", PhotonGridSettings { photons, cache_resolution, output_resolution, similarity: Similarity::Off, ..Default::default() }),
        ] {
            let (e, rep, secs) = against(name, s);
            print(name, what, &e, &rep, secs);
        }
    }
}

/// Settings of the fast tests: 2^17 photons (under a second on one core for these scenes).
fn fast() -> PhotonGridSettings {
    PhotonGridSettings { photons: 1 << 17, ..Default::default() }
}

/// With photons carrying single scattering too and a tiny albedo (almost nothing scatters
/// twice), S is the photons' single scattering, which must match the compositor's independent
/// ray-marched single-scattering AOV: checks the deposits' normalisation (rho / majorant over
/// the cell's mass), LightSampler's power, the lobe (g' = 1 for the unscattered sun) and the
/// phase convention together.
#[test]
fn single_scattering_from_photons_matches_compositor() {
    for g in [0.0f32, 0.7] {
        let mut sc = case("cube_g0");
        sc.medium.albedo = Vec3::splat(0.02);
        sc.medium.g = g;
        let (out, _) = solve(&sc, PhotonGridSettings { single_scattering: SingleScattering::Photons, photons: 1 << 18, ..Default::default() });
        let (e, ratio) = against_single_scattering(&sc, &out.scattering);
        eprintln!("g {g}: photon single scattering vs compositor: rel. RMSE {e:.4}, mean x{ratio:.4}");
        assert!(e < 0.1 && (ratio - 1.0).abs() < 0.05, "g {g}: rel. RMSE {e}, mean ratio {ratio}");
    }
}

/// Albedo 0: no photon survives its first collision, the cache stays empty and S is exactly
/// the compositor's single scattering (which is zero here too, sigma_s being 0); and with
/// albedo 0 all the energy a photon brings is absorbed or escapes.
#[test]
fn albedo_zero_gives_exactly_single_scattering() {
    let mut sc = case("cube_g07");
    sc.medium.albedo = Vec3::ZERO;
    let s = fast();
    let (out, rep) = solve(&sc, s.clone());
    let dirs = dome_directions_for(&sc, CompositeOptions::default().dome_directions);
    let single = single_scattering_grid(&sc, s.output_resolution, dirs).unwrap();
    assert_eq!(out.scattering.data, single.data);
    let e = &rep.energy;
    let balance = (e.escaped + e.absorbed + e.cut - e.emitted).abs().max_element() / e.emitted.max_element();
    assert!(balance < 1e-6 && e.absorbed.x > 0.0, "{e:?}");
}

/// Energy (issue 17): albedo 1 and a grey medium keep every photon's weight at 1, so the
/// cutoff never acts and escaped = emitted (to f64 rounding); with albedo 0.9 escaped +
/// absorbed + cut = emitted, and the cutoff's share is reported.
#[test]
fn energy_is_accounted_for() {
    let mut sc = case("cube_g07");
    let (_, rep) = solve(&sc, fast());
    let e = rep.energy;
    let rel = |v: glam::DVec3| (v - e.emitted).abs().max_element() / e.emitted.max_element();
    assert!(rel(e.escaped) < 1e-9 && e.cut == glam::DVec3::ZERO, "albedo 1: {e:?}");
    sc.medium.albedo = Vec3::splat(0.9);
    let (_, rep) = solve(&sc, PhotonGridSettings { cutoff: 0.5, ..fast() });
    let e = rep.energy;
    eprintln!("albedo 0.9, cutoff 0.5: escaped {:.4} absorbed {:.4} cut {:.4} of emitted", e.escaped.x / e.emitted.x, e.absorbed.x / e.emitted.x, e.cut.x / e.emitted.x);
    assert!(rel(e.escaped + e.absorbed + e.cut) < 1e-6 && e.cut.x > 0.0, "{e:?}");
}

/// The same seed gives the same S (photons in fixed batches, summed in order); another seed
/// gives another sample.
#[test]
fn deterministic_for_a_seed() {
    let sc = case("cube_g07");
    let s = PhotonGridSettings { photons: 1 << 14, ..Default::default() };
    let a = solve(&sc, s.clone()).0.scattering.data;
    let b = solve(&sc, s.clone()).0.scattering.data;
    let c = solve(&sc, PhotonGridSettings { seed: 2, ..s }).0.scattering.data;
    assert_eq!(a, b);
    assert_ne!(a, c);
}

/// The lobe of the unscattered sun is the sun: direction along the beam, g' near 1 (every
/// deposit's direction is the same; 0.999 is the clamp).
#[test]
fn lobe_of_direct_sun_points_along_the_beam() {
    let mut sc = case("cube_g0");
    sc.medium.albedo = Vec3::splat(1e-4);
    let pg = PhotonGrid::new(PhotonGridSettings { single_scattering: SingleScattering::Photons, photons: 1 << 14, ..Default::default() }).unwrap();
    let lobes = pg.lobes(&sc, &[Vec3::ZERO]).unwrap();
    let sun = Vec3::new(0.4, -0.5, -0.75).normalize();
    assert!(lobes[0].g > 0.99 && lobes[0].direction.dot(sun) > 0.999 && lobes[0].order < 0.01, "{:?}", lobes[0]);
}

#[test]
fn settings_parse_and_reject() {
    let ok: serde_json::Value = serde_json::json!({"name": "photon-grid", "photons": 1000, "similarity": "sqrt", "single_scattering": "photons", "angular": "camera"});
    let pg = PhotonGrid::from_settings(ok.as_object().unwrap()).unwrap();
    assert_eq!(pg.settings.similarity, Similarity::Sqrt);
    assert_eq!(pg.settings.angular, Angular::Camera);
    // Camera deposits are CPU only and keep no view-independent lobes: both said, not ignored.
    assert!(pg.settings.needs_cpu().is_some() && PhotonGridSettings::default().needs_cpu().is_none());
    assert!(pg.lobes(&case("cube_g0"), &[Vec3::ZERO]).is_err());
    for bad in [serde_json::json!({"photon": 10}), serde_json::json!({"similarity": "cubic"}), serde_json::json!({"cutoff": 1.0}), serde_json::json!({"angular": "sphere"})] {
        assert!(PhotonGrid::from_settings(bad.as_object().unwrap()).is_err(), "{bad} accepted");
    }
}

// Against the converged references (fixtures written by the reference path tracer; their own
// noise: cubes 0.5% (g 0) to 3% (g 0.9) of the image, cloud 2.2% image / 4.2% grid). Bounds:
// the error measured with `fast()` when written plus 10% and 0.01 (a ratchet, as pop/tests.rs).
// Measured (image / grid rel. RMSE, image mean ratio), two lobes per cell: cube g 0 0.031 /
// 0.066 (x0.999), cube g 0.9 0.157 / 0.246 (x0.908), plume 0.204 / 0.222 (x0.965), cloud
// 0.210 / 0.295 (x0.962), in 0.1 to 0.5 s each. POP with its test settings: 0.18, 0.40, 0.39,
// 0.49 (image). At 2^20 photons the cloud gives 0.153 / 0.240 and the cube g 0.9 0.134 / 0.169:
// the rest is the lobe model, not noise (cache resolutions 12 / 24 / 40 changed the one-lobe
// cloud image only between 0.203 and 0.209). Keeping the light past the similarity threshold
// apart as an isotropic term (the brief's "isotropic part") was measured worse with one lobe
// (cloud image 0.203 -> 0.239) and is not done.

/// photon-grid at `fast()` (a ratchet row's solver).
fn fast_pg() -> PhotonGrid {
    PhotonGrid::new(fast()).unwrap()
}

/// A ratchet row's further print: where the photons' power went.
fn print_energy(name: &str, _: &Errors, out: &SolveOutput) {
    eprintln!("{name} [fast]: {}", energy(out.report::<PhotonGridReport>().expect("photon-grid's report")));
}

against_reference! {
    solver: "photon-grid";
    then: print_energy;
    cube_g0_against_reference: "cube_g0", fast_pg(), 0.044, 0.082;
    cube_g09_against_reference: "cube_g09", fast_pg(), 0.183, 0.281;
    plume_against_reference: "plume", fast_pg(), 0.235, 0.254;
    dense_cloud_against_reference: "cloud", fast_pg(), 0.241, 0.334;
}

/// `angular: camera` (each deposit weighted by the exact phase towards the camera, no lobe
/// model; with the similarity switch off, as settings.rs advises) at 2^19 photons: the lobes'
/// darkening at g 0.9 goes (cube g 0.9 image mean x0.916 with the lobes at 2^18; with the
/// camera measured x1.013, bound 3%: the cube's image noise at this count is 0.14), and both
/// scenes' errors are ratcheted as the lobes' are (measured + 10% + 0.01): cube g 0.9 0.145 /
/// 0.314 (image / grid), dense cloud 0.155 / 0.174 (x0.990). Noisier than the lobes at
/// few photons (the phase at g 0.9 spans 0.02..190 x its mean), better on the cloud from 2^22.
#[test]
fn camera_deposits_remove_the_lobe_bias() {
    for (name, max_image, max_grid) in [("cube_g09", 0.170, 0.355), ("cloud", 0.180, 0.202)] {
        let (e, rep, secs) = against(name, PhotonGridSettings { photons: 1 << 19, angular: Angular::Camera, similarity: Similarity::Off, ..Default::default() });
        print(name, "camera", &e, &rep, secs);
        assert!(e.image <= max_image && e.grid <= max_grid, "{name}: {e}");
        if name == "cube_g09" {
            assert!((e.image_ratio - 1.0).abs() < 0.03, "cube g 0.9 image mean x{:.3}", e.image_ratio);
        }
    }
}

/// A backend that traces nothing (a stand-in for the GPU's, whose kernel keeps lobes only).
struct NoTracing;

impl super::backend::PhotonBackend for NoTracing {
    fn trace_generations(&self, _: &super::backend::TraceJob, _: &[u64]) -> crate::error::Result<Vec<super::ring::Generation>> {
        Err(crate::error::Error::InvalidArgument("this backend traces nothing".into()))
    }
}

/// Camera weights are traced on the CPU whatever backend the solve is given (the same S as
/// the CPU backend's, bit for bit), while the lobes go to the backend (here: its error).
#[test]
fn camera_weights_trace_on_the_cpu_whatever_the_backend() {
    let sc = case("cube_g07");
    let s = PhotonGridSettings { photons: 1 << 12, angular: Angular::Camera, ..Default::default() };
    let pg = PhotonGrid::new(s.clone()).unwrap();
    let (no_tracing, cpu): (Box<dyn PhotonBackend>, Box<dyn PhotonBackend>) = (Box::new(NoTracing), Box::new(super::backend::CpuBackend));
    let a = pg.solve(&sc, &mut SolveCtx::new(&NoProgress).on(&no_tracing)).unwrap().scattering.data;
    let b = pg.solve(&sc, &mut SolveCtx::new(&NoProgress).on(&cpu)).unwrap().scattering.data;
    assert_eq!(a, b);
    let lobes = PhotonGrid::new(PhotonGridSettings { angular: Angular::Lobes, ..s }).unwrap();
    assert!(lobes.solve(&sc, &mut SolveCtx::new(&NoProgress).on(&no_tracing)).is_err());
}

/// A medium of at most `output_resolution` voxels a side is returned on its own voxels:
/// the dense cloud's 64 voxels at the default 64 give 66 points a side (its one-voxel ramp on
/// each side included), every point on a voxel centre; a coarser output keeps its resolution.
#[test]
fn output_grid_sits_on_the_voxels() {
    let sc = case("cloud");
    let dim = PhotonGridSettings::default().output_dim(&sc.medium);
    assert_eq!(dim, 66);
    let grid = crate::stages::ScatteringGrid::over_medium(&sc.medium, dim).unwrap();
    let to_voxel = sc.medium.index_to_world.inverse() * grid.index_to_world;
    let [nx, ny, nz] = grid.dims;
    for (i, j, k) in [(0, 0, 0), (nx - 1, ny - 1, nz - 1), (nx / 2, ny / 3, nz / 5)] {
        let q = to_voxel.transform_point3(Vec3::new(i as f32, j as f32, k as f32));
        assert!((q - q.round()).abs().max_element() < 1e-3, "point ({i}, {j}, {k}) at voxel index {q}");
    }
    assert_eq!(PhotonGridSettings { output_resolution: 48, ..Default::default() }.output_dim(&sc.medium), 48);
}

/// Where the bias at g 0.9 comes from (issue 17): prints, per fixture (PG_CASE selects; the
/// shared `fixture_scene`s, plume_point included), image / grid errors and the image mean ratio
/// of variants that each change one thing: the upsampling (trilinear, the paper's Sec. 4.3),
/// the lobe model (`oracle`: deposits weighted by the exact phase towards the camera, so only
/// the spatial binning is left), the cache resolution and the similarity switch. PG_PHOTONS:
/// photons (default 2^18); PG_VARIANTS: the variants whose name contains one of its
/// comma-separated words (all when unset).
///
/// Measured (2026-11-24, image rel. RMSE (image mean ratio) / grid rel. RMSE (grid ratio)):
/// - cube g 0.9 at 2^18: trilinear 0.131 (x0.916) / 0.199; physical 0.133 (x0.928) / 0.165;
///   oracle 0.194 (x1.006) / 0.452, oracle physical 0.149 (x1.011) / 0.250. The similarity
///   switch never acts (1.5 scatterings per photon, switch after 29): off and sqrt are
///   identical. Cache 12 x0.935; 24 and 48 are the same grid (cells are capped at the 16
///   voxels). So the x0.92 is the lobe model: one HG lobe per cell fitted to the mean cosine
///   misses the shape of the once-scattered light's angular distribution (HG(g) about the
///   sun times the path length behind each direction); with the exact phase per deposit the
///   mean is right and only noise is left (which the lobe's smoothing otherwise hides).
/// - dense cloud at 2^20: trilinear 0.153 (x0.982) / 0.241 (x1.161); physical 0.153 /
///   0.242; switch off 0.154 / 0.200 (x1.092); sqrt 0.158 / 0.331 (x1.281); cache 12 0.177
///   / 0.269, cache 48 0.147 (x1.006) / 0.287; oracle 0.174 (x1.092) / 0.227 (x1.099), at
///   cache 48 0.237 / 0.516 (x1.105). The grid's x1.16 is about 7% the switch (x1.09 off)
///   and the rest not the lobe model (the oracle keeps x1.10) nor the cell size (cache 48
///   keeps it). The image's 0.15 floor moves with none of these by more than 0.01 at 2^20.
///   Not the default: similarity off costs 12% more scatterings here and far more in thicker
///   media, which the switch exists for.
///   Superseded by `floor_anatomy` (below): at 2^20 the oracle's noise hid its gain, and
///   the output grid's 64 points between the 64-voxel cloud's voxel centres made it x1.07
///   too bright. On the medium's own voxels (settings.rs `output_dim`) and at 2^24 the
///   oracle (now `angular: camera`) reaches 0.060 against the lobes' 0.14 floor.
/// - The principled fix of the lobe-model bias (not built): a second angular moment per cell
///   (the tensor sum of d d^T) and a fit of isotropic + HG(h) matching both Legendre
///   moments (k1 = a h, k2 = a h^2), whose convolution with HG(g) is still closed-form
///   (App. C); it changes the cache layout on the CPU and the GPU (15 sums per cell, not 9).
///   Measured since (`floor_anatomy`, settings.rs `angular`): on the cloud the lobe's error is
///   the flat, half-range radiance leaving a surface, whose k2 is below k1^2, which no
///   positive mixture of coaxial HG lobes (k_l = h^l each) can match: the fit would need a
///   negative isotropic part there.
#[test]
#[ignore]
fn bias_sources() {
    use crate::solvers::testing::{fixture_scene, selected};
    let photons = env_u32("PG_PHOTONS", 1 << 18);
    let only = std::env::var("PG_VARIANTS").unwrap_or_default();
    let base = PhotonGridSettings { photons, ..Default::default() };
    let physical = PhotonGridSettings { upsampling: Upsampling::Physical, ..base.clone() };
    let variants: Vec<(&str, PhotonGridSettings, bool)> = vec![
        ("trilinear", base.clone(), false),
        ("physical", physical.clone(), false),
        ("oracle trilinear", base.clone(), true),
        ("oracle physical", physical.clone(), true),
        ("switch-off trilinear", PhotonGridSettings { similarity: Similarity::Off, ..base.clone() }, false),
        ("switch-sqrt trilinear", PhotonGridSettings { similarity: Similarity::Sqrt, ..base.clone() }, false),
        ("cache12 trilinear", PhotonGridSettings { cache_resolution: 12, ..base.clone() }, false),
        ("cache48 trilinear", PhotonGridSettings { cache_resolution: 48, ..base.clone() }, false),
        ("cache12 physical", PhotonGridSettings { cache_resolution: 12, ..physical.clone() }, false),
        ("cache48 physical", PhotonGridSettings { cache_resolution: 48, ..physical.clone() }, false),
        ("cache48 oracle trilinear", PhotonGridSettings { cache_resolution: 48, ..base.clone() }, true),
    ];
    for name in selected(&["cube_g0", "cube_g07", "cube_g09", "plume", "plume_point", "cloud"], "PG_CASE") {
        let sc = fixture_scene(name);
        for (what, s, oracle) in &variants {
            if !only.is_empty() && !only.split(',').any(|w| what.contains(w)) {
                continue;
            }
            let s = if *oracle { PhotonGridSettings { angular: Angular::Camera, ..s.clone() } } else { s.clone() };
            let pg = PhotonGrid::new(s).unwrap();
            let t = std::time::Instant::now();
            let (out, rep) = pg.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap();
            let secs = t.elapsed().as_secs_f64();
            print(name, what, &errors_against_fixture(name, &sc, &out.scattering), &rep, secs);
        }
    }
}

/// Where on the image the error is (PG_CASE, default cloud; PG_PHOTONS, default 2^20; PG_CACHE;
/// PG_ORACLE): the pixels split by the fixture's brightness into quarters, each quarter's share
/// of the squared error and its mean ratio, for the whole image and its multiple-scattering
/// part (background pixels, zero in the fixture, make the dim quarters' ratios meaningless).
///
/// Measured on the cloud (2026-11-24; image rel. RMSE, mean ratio of the cloud's dimmer and
/// brighter quarter of pixels): cache 24 at 2^22 0.149, dim x1.17 / bright x0.94 (too little
/// contrast: light spread from the lit flank into the shadowed base); with the exact phase
/// per deposit (PG_ORACLE) x1.27 / x1.04 (the lobe model darkens by ~8%, the blur stays);
/// cache 32 at 2^22 0.139 (x1.135 / x0.957), at 2^24 0.137; cache 48 at 2^24 0.137 (x1.087 /
/// x0.988); cache 64 (the voxels) at 2^22 0.151 and at 2^24 0.151 (x1.020 / x1.029, 40 s):
/// the contrast is right at voxel cells, yet the error stays at 0.15 with 16M photons, and the
/// grid at x1.15 (the similarity switch's share is ~7%, bias_sources). What is left is not
/// noise, not the cells' size and not the contrast: `floor_anatomy` found it (the lobe of the
/// light scattered twice or more, and the output grid off the voxels).
#[test]
#[ignore]
fn error_by_brightness() {
    use crate::solvers::testing::{fixture_scene, load_fixture, SolverOutput};
    let name = std::env::var("PG_CASE").unwrap_or_else(|_| "cloud".into());
    let sc = fixture_scene(&name);
    let fx = load_fixture(&name);
    // PG_ORACLE=1: deposits weighted by the exact phase towards the camera (`angular: camera`).
    let angular = if env_u32("PG_ORACLE", 0) == 1 { Angular::Camera } else { Angular::Lobes };
    let s = PhotonGridSettings { photons: env_u32("PG_PHOTONS", 1 << 20), cache_resolution: env_u32("PG_CACHE", 24), angular, ..Default::default() };
    let pg = PhotonGrid::new(s).unwrap();
    let t = std::time::Instant::now();
    let out = SolverOutput::of(&sc, &pg.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap().scattering);
    eprintln!("{name}: {} ({:.1} s)", crate::solvers::testing::Errors::against(&out, &fx), t.elapsed().as_secs_f64());
    for (what, mine, reference) in [("image", out.image.clone(), fx.image()), ("multiple", out.multiple.clone(), fx.multiple().unwrap_or_default())] {
        if reference.is_empty() {
            continue;
        }
        let mut order: Vec<usize> = (0..reference.len()).collect();
        order.sort_by(|&a, &b| reference[a].element_sum().total_cmp(&reference[b].element_sum()));
        let total: f64 = mine.iter().zip(&reference).map(|(a, b)| (*a - *b).as_dvec3().length_squared()).sum();
        for (q, part) in order.chunks(order.len().div_ceil(4)).enumerate() {
            let err: f64 = part.iter().map(|&i| (mine[i] - reference[i]).as_dvec3().length_squared()).sum();
            let (m, r): (f64, f64) = part.iter().fold((0.0, 0.0), |(m, r), &i| (m + mine[i].element_sum() as f64, r + reference[i].element_sum() as f64));
            eprintln!("{name} {what} quarter {q} (dim to bright): share of squared error {:.3}, mean ratio x{:.3}", err / total, m / r.max(1e-30));
        }
    }
}

/// Anatomy of the dense cloud's error floor (issue 17; PG_PHOTONS default 2^20, PG_CACHE 24,
/// PG_OUTPUT 64, PG_ORACLE=1 for `angular: camera`, PG_SWITCH=0 for no similarity switch):
/// the image error split into its single-scattering part (the compositor's AOV against the
/// fixture's image minus its multiple AOV) and its multiple part, each over the whole image's
/// norm (so their squares add up to the image's); the silhouette pixels' share (composited
/// alpha < 0.95); the compositor's own sampling (2 x 2 rays a pixel against 6 x 6 at a quarter
/// voxel step, same S); a map of each pixel's error; and the grid split by optical depth
/// towards the sun.
///
/// Measured (2026-11-24, cache 32, 2^24 photons unless said; image rel. RMSE (mean ratio)):
/// - Single scattering is not it: its part of the image error is 0.003 (it is 3% of the
///   image from this camera); the compositor's own sampling (2 x 2 rays, half-voxel steps)
///   differs from 6 x 6 rays at quarter-voxel steps by 0.017; the silhouette (88 pixels of
///   alpha < 0.95) holds 0.04-0.07 of the error in every variant.
/// - The lobes: 0.137 (x0.994). The pixel map: the shadowed foot of the cloud (rows 15-17)
///   20-30% of the image's rms too dark, the sunlit right flank 15-35% too bright. The grid
///   is x1.45 too bright where the optical depth to the sun is 10-30 (x1.27 without the
///   switch).
/// - The exact phase per deposit (PG_ORACLE): 0.097 (x1.079), switch off 0.090 (x1.066),
///   grid 0.065 (x1.007): the foot is right; what is left is a uniform brightening.
/// - That brightening is the output grid: `over_medium(64)` spans the 64 voxels plus the
///   one-voxel ramp on each side with 64 points, 1.03 voxels apart, so S is sampled between
///   voxel centres. On the voxels (66 points, settings.rs `output_dim`), exact phase, switch
///   off: 0.087 (x1.023) at 2^22, 0.060 (x1.017) at 2^24, grid 0.066 (x1.006). The lobes on
///   the voxels: 0.140 (x0.943) at 2^22: their darkening had hidden the grid's brightening.
/// - Which lobe: camera weights on the twice-or-more scattered lobe alone give the
///   all-camera result (0.0866 at 2^22); on the once-scattered lobe alone the lobes' (0.148).
/// - Cache resolution, camera weights, switch off, 2^22: 24 0.088, 32 0.087, 48 0.091.
#[test]
#[ignore]
fn floor_anatomy() {
    use crate::compositor::composite;
    use crate::solvers::testing::{fixture_scene, load_fixture, rgb, FIXTURE_GRID};
    let sc = fixture_scene("cloud");
    let fx = load_fixture("cloud");
    let mut s = PhotonGridSettings { photons: env_u32("PG_PHOTONS", 1 << 20), cache_resolution: env_u32("PG_CACHE", 24), output_resolution: env_u32("PG_OUTPUT", 64), ..Default::default() };
    // PG_SWITCH=0: no similarity switch; PG_CUTOFF=0: no cutoff; PG_ORACLE=1 (bias_sources).
    if env_u32("PG_SWITCH", 1) == 0 {
        s.similarity = Similarity::Off;
    }
    if env_u32("PG_CUTOFF", 1) == 0 {
        s.cutoff = 0.0;
    }
    if env_u32("PG_ORACLE", 0) == 1 {
        s.angular = Angular::Camera;
    }
    let pg = PhotonGrid::new(s).unwrap();
    let t = std::time::Instant::now();
    let (out, rep) = pg.solve(&sc, &mut SolveCtx::new(&NoProgress)).map(SolveOutput::split::<PhotonGridReport>).unwrap();
    print("cloud", "floor", &errors_against_fixture("cloud", &sc, &out.scattering), &rep, t.elapsed().as_secs_f64());
    let out = out.scattering;
    let opts = CompositeOptions { transparent: true, ..Default::default() };
    let img = composite(&sc, &out, &opts).unwrap();
    let fine = composite(&sc, &out, &CompositeOptions { subpixels: 6, step_voxels: 0.25, single_resolution: 64, ..opts.clone() }).unwrap();
    let (mine, fine_rgb) = (rgb(&img), rgb(&fine));
    let mine_single = img.aov("single").unwrap().to_vec();
    let (ref_img, ref_multi) = (fx.image(), fx.multiple().unwrap());
    let ref_single: Vec<Vec3> = ref_img.iter().zip(&ref_multi).map(|(a, b)| *a - *b).collect();
    let mine_multi: Vec<Vec3> = mine.iter().zip(&mine_single).map(|(a, b)| *a - *b).collect();
    let norm: f64 = ref_img.iter().map(|p| p.as_dvec3().length_squared()).sum();
    let part = |a: &[Vec3], b: &[Vec3], keep: &dyn Fn(usize) -> bool| -> f64 {
        (a.iter().zip(b).enumerate().filter(|(i, _)| keep(*i)).map(|(_, (x, y))| (*x - *y).as_dvec3().length_squared()).sum::<f64>() / norm).sqrt()
    };
    let all = |_: usize| true;
    let m = |v: &[Vec3]| crate::solvers::testing::mean(v);
    eprintln!(
        "image {:.4} (x{:.3}); single part {:.4} (mine {:.4} / ref {:.4} of the image mean), multiple part {:.4} (x{:.3})",
        part(&mine, &ref_img, &all),
        m(&mine) / m(&ref_img),
        part(&mine_single, &ref_single, &all),
        m(&mine_single) / m(&ref_img),
        m(&ref_single) / m(&ref_img),
        part(&mine_multi, &ref_multi, &all),
        m(&mine_multi) / m(&ref_multi)
    );
    for r in [48u32, 64, 66, 131] {
        let single = composite(&sc, &out, &CompositeOptions { single_resolution: r, ..opts.clone() }).unwrap();
        let a = single.aov("single").unwrap();
        eprintln!("compositor single AOV at single_resolution {r}: {:.4} of the image, mean x{:.4} of the reference's", part(a, &ref_single, &all), m(a) / m(&ref_single));
    }
    let alpha: Vec<f32> = fine.rgba.iter().map(|p| p.w).collect();
    let rim = |i: usize| alpha[i] < 0.95 && alpha[i] > 0.0;
    eprintln!(
        "silhouette ({} pixels, alpha < 0.95): {:.4} of the image error; compositor 6x6 rays / 1/4 voxel steps against its default: {:.4}; fine against the fixture {:.4}",
        (0..alpha.len()).filter(|&i| rim(i)).count(),
        part(&mine, &ref_img, &rim),
        crate::image::relative_rmse(&mine, &fine_rgb),
        part(&fine_rgb, &ref_img, &all)
    );
    // Per pixel: (mine - ref) / the image's rms, in percent (blank: background).
    let rms = (norm / ref_img.len() as f64).sqrt();
    let n = sc.camera.width as usize;
    for (row, (a, b)) in mine.chunks(n).zip(ref_img.chunks(n)).enumerate() {
        let cells: String = a.iter().zip(b).map(|(x, y)| if y.max_element() <= 0.0 { "    ".to_string() } else { format!("{:4.0}", 100.0 * (x.x - y.x) as f64 / rms) }).collect();
        eprintln!("{row:2} {cells}");
    }
    // The grid against the fixture's by optical depth towards the sun.
    let frame = crate::stages::ScatteringGrid::over_medium(&sc.medium, FIXTURE_GRID).unwrap();
    let grid = crate::solvers::testing::resample(&out, &frame);
    let fg = fx.grid();
    let to_sun = crate::solvers::testing::cloud::to_sun();
    let gnorm: f64 = fg.iter().map(|p| p.as_dvec3().length_squared()).sum();
    let mut bins = [(0.0f64, 0.0f64, 0.0f64, 0usize); 5];
    let edges = [1.0f32, 3.0, 10.0, 30.0];
    for (i, (a, b)) in grid.iter().zip(&fg).enumerate() {
        let [nx, ny, _] = frame.dims;
        let p = frame.position(i as u32 % nx, (i as u32 / nx) % ny, i as u32 / (nx * ny));
        let tau = crate::solvers::testing::cloud::optical_depth(&sc.medium, p, p + 3.0 * to_sun);
        let k = edges.iter().position(|e| tau < *e).unwrap_or(4);
        bins[k].0 += (*a - *b).as_dvec3().length_squared() / gnorm;
        bins[k].1 += a.element_sum() as f64;
        bins[k].2 += b.element_sum() as f64;
        bins[k].3 += 1;
    }
    for (k, (e, a, b, c)) in bins.iter().enumerate() {
        eprintln!("grid, optical depth to the sun bin {k} (edges 1, 3, 10, 30): {c} points, share of squared error {e:.3}, mean ratio x{:.3}", a / b.max(1e-30));
    }
}
