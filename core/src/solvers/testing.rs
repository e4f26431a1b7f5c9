//! The test harness shared by every solver's tests (compiled for this crate's tests, and with
//! the `testing` feature for volscatter-gpu's and the cross-language tests and the benchmark
//! examples; never in a plain build): the converged reference fixtures in `fixtures/` (image +
//! scattering grid + their own noise) and their scenes (scenes.rs, cloud.rs), the metrics every
//! solver is measured by against them (DESIGN.md "Engineering rules"), the ratchet check
//! against them written once (`check_against_reference`, the `against_reference!` table every
//! solver's ratchets are rows of), and the checks written once and run over every solver
//! (white furnace, energy balance: furnace.rs; every registry name in every harness:
//! coverage.rs).

pub mod cloud;
#[cfg(test)]
mod coverage;
#[cfg(test)]
mod extremes;
#[cfg(test)]
mod furnace;
#[cfg(test)]
mod lamp_probe;
pub mod scenes;

use crate::solvers::{SolveCtx, SolveOutput, Solver};
use glam::{Affine3A, IVec3, Vec3};

use crate::compositor::{composite, CompositeOptions};
use crate::image::{relative_rmse, Image};
use crate::medium::{DensityGrid, GridLimits, Medium};
use crate::scene::Scene;
use crate::solvers::reference::{Reference, ReferenceSettings};
use crate::stages::{NoProgress, ScatteringGrid, Timings};

/// Resolution (largest dimension) of the fixtures' scattering grids, on which every solver's
/// grid is compared: coarse, so that the reference converges per grid point in minutes.
pub const FIXTURE_GRID: u32 = 10;

/// A converged reference solution, computed once by a `regenerate_*` test (`#[ignore]`d: the
/// path tracer needs minutes for these, the solvers' tests must run in seconds) and stored as
/// `fixtures/<name>.json`.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Fixture {
    pub spp: u32,
    pub grid_spp: u32,
    /// Composited image (transparent background), RGB, row-major.
    pub image: Vec<[f32; 3]>,
    /// Multiple-scattering AOV of the reference (image minus single scattering). Absent from
    /// the radial fixtures, which were written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub multiple: Option<Vec<[f32; 3]>>,
    pub grid_dims: [u32; 3],
    pub grid: Vec<[f32; 3]>,
    /// Relative RMSE of the fixture's own noise (half the rel. RMSE between its two
    /// independent halves), image and grid.
    pub noise_image: f64,
    pub noise_grid: f64,
}

impl Fixture {
    pub fn image(&self) -> Vec<Vec3> {
        vecs(&self.image)
    }
    pub fn grid(&self) -> Vec<Vec3> {
        vecs(&self.grid)
    }
    pub fn multiple(&self) -> Option<Vec<Vec3>> {
        self.multiple.as_deref().map(vecs)
    }
}

pub fn fixture_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/solvers/fixtures").join(format!("{name}.json"))
}

pub fn load_fixture(name: &str) -> Fixture {
    let text = std::fs::read_to_string(fixture_path(name))
        .unwrap_or_else(|e| panic!("fixture {name} missing ({e}): run its `regenerate_*` test with --run-ignored only"));
    serde_json::from_str(&text).unwrap()
}

/// The scene of any shared fixture by name: the dense cloud, the local-light cases
/// (`plume_*`, `fig10_*`), the dome cases (`dome_*`) and the distant-light cases (scenes.rs).
pub fn fixture_scene(name: &str) -> Scene {
    if name == "cloud" {
        cloud::cloud_scene()
    } else if name.starts_with("dome_") {
        scenes::dome_case(name)
    } else if name.starts_with("plume_") || name.starts_with("fig10") {
        scenes::local_light_case(name)
    } else {
        scenes::distant_case(name)
    }
}

/// Every shared fixture's name (each has a `fixtures/<name>.json` and a `fixture_scene`).
pub fn fixture_names() -> Vec<&'static str> {
    let mut names = vec!["cloud"];
    names.extend(scenes::DISTANT_CASES);
    names.extend(scenes::LOCAL_LIGHT_CASES);
    names.extend(scenes::DOME_CASES);
    names
}

/// A host that has cancelled: every progress callback answers stop.
pub struct Cancelled;

impl crate::stages::Progress for Cancelled {
    fn update(&self, _: &str, _: f32) -> bool {
        false
    }
    fn cancelled(&self) -> bool {
        true
    }
}

/// An unsigned setting of a `regenerate_*` / `explore*` test from the environment.
pub fn env_u32(key: &str, default: u32) -> u32 {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The cases whose name contains the environment variable `key` (all when it is unset).
pub fn selected<'a>(cases: &'a [&'a str], key: &str) -> impl Iterator<Item = &'a str> + 'a {
    let only = std::env::var(key).unwrap_or_default();
    cases.iter().copied().filter(move |n| only.is_empty() || n.contains(only.as_str()))
}

/// Renders `sc` with the reference path tracer in two independent halves (seeds 1 and 2) of
/// `spp` paths per pixel and `grid_spp` per grid point (on a `FIXTURE_GRID` grid), and stores
/// their mean as the fixture `name`, with its noise from their difference.
pub fn regenerate_fixture(name: &str, sc: &Scene, spp: u32, grid_spp: u32) -> Fixture {
    let t = std::time::Instant::now();
    let half = |seed: u64| {
        let r = Reference::new(ReferenceSettings { spp: spp / 2, seed, grid_resolution: FIXTURE_GRID, grid_spp: grid_spp / 2, transparent: true, ..Default::default() })
            .unwrap();
        let img = r.render_image(sc, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
        let grid = r.scattering_grid(sc, &NoProgress, &mut Timings::default()).unwrap();
        (img, grid)
    };
    let (a, ga) = half(1);
    let (b, gb) = half(2);
    let avg = |x: &[Vec3], y: &[Vec3]| x.iter().zip(y).map(|(p, q)| ((*p + *q) * 0.5).to_array()).collect::<Vec<_>>();
    let fx = Fixture {
        spp,
        grid_spp,
        image: avg(&rgb(&a), &rgb(&b)),
        multiple: Some(avg(a.aov("multiple").unwrap(), b.aov("multiple").unwrap())),
        grid_dims: ga.dims,
        grid: avg(&ga.data, &gb.data),
        noise_image: 0.5 * relative_rmse(&rgb(&a), &rgb(&b)),
        noise_grid: 0.5 * relative_rmse(&ga.data, &gb.data),
    };
    std::fs::create_dir_all(fixture_path(name).parent().unwrap()).unwrap();
    std::fs::write(fixture_path(name), serde_json::to_string(&fx).unwrap()).unwrap();
    eprintln!("{name}: noise image {:.4} grid {:.4} ({:.0} s)", fx.noise_image, fx.noise_grid, t.elapsed().as_secs_f64());
    fx
}

/// Regenerates the fixtures of the `cases` selected by the environment variable `select_key`
/// (`selected`), each from its scene `case(name)`.
pub fn regenerate_selected(cases: &[&str], select_key: &str, case: impl Fn(&str) -> Scene, spp: u32, grid_spp: u32) {
    for name in selected(cases, select_key) {
        regenerate_fixture(name, &case(name), spp, grid_spp);
    }
}

/// A solver's composite against the compositor's own single-scattering AOV of the same image
/// (rel. RMSE, mean ratio): with a tiny albedo a solver's S is its single scattering, which the
/// compositor computes independently (ray-marched shadow rays).
pub fn against_single_scattering(sc: &Scene, scattering: &ScatteringGrid) -> (f64, f64) {
    let img = composite(sc, scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
    let (image, single) = (scattered(&img), img.aov("single").unwrap());
    (relative_rmse(&image, single), mean(&image) / mean(single))
}

/// The light a composite's S gives: its RGB less the medium's emission seen directly (the
/// `emission` AOV, which does not depend on the solver).
pub fn scattered(img: &Image) -> Vec<Vec3> {
    match img.aov("emission") {
        Some(e) => img.rgba.iter().zip(e).map(|(p, e)| p.truncate() - *e).collect(),
        None => rgb(img),
    }
}

/// The RGB of an image, without alpha.
pub fn rgb(img: &Image) -> Vec<Vec3> {
    img.rgba.iter().map(|p| p.truncate()).collect()
}

pub fn vecs(v: &[[f32; 3]]) -> Vec<Vec3> {
    v.iter().map(|a| Vec3::from(*a)).collect()
}

/// Mean of the channel sums (so ratios of means weigh R, G, B alike).
pub fn mean(v: &[Vec3]) -> f64 {
    v.iter().map(|p| p.x as f64 + p.y as f64 + p.z as f64).sum::<f64>() / v.len().max(1) as f64
}

/// What a solver's scattering grid gives, in the fixtures' terms: the composited image (RGB,
/// transparent background, without the emission seen directly), its multiple-scattering part (image minus the compositor's
/// single-scattering AOV, which the compositor computes the same way for every solver) and the
/// grid resampled (trilinear) onto the fixtures' `FIXTURE_GRID` frame.
pub struct SolverOutput {
    pub image: Vec<Vec3>,
    pub multiple: Vec<Vec3>,
    pub frame: ScatteringGrid,
    pub grid: Vec<Vec3>,
}

impl SolverOutput {
    pub fn of(sc: &Scene, scattering: &ScatteringGrid) -> Self {
        let img = composite(sc, scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
        let image = scattered(&img);
        let multiple = image.iter().zip(img.aov("single").unwrap()).map(|(a, b)| *a - *b).collect();
        let frame = ScatteringGrid::over_medium(&sc.medium, FIXTURE_GRID).unwrap();
        let grid = resample(scattering, &frame);
        SolverOutput { image, multiple, frame, grid }
    }
}

/// `grid` looked up (trilinear, zero outside) at every point of `frame`, in `frame`'s order.
pub fn resample(grid: &ScatteringGrid, frame: &ScatteringGrid) -> Vec<Vec3> {
    let to_grid = grid.index_to_world.inverse();
    let mut out = Vec::with_capacity(frame.len());
    for k in 0..frame.dims[2] {
        for j in 0..frame.dims[1] {
            for i in 0..frame.dims[0] {
                out.push(grid.sample_index(to_grid.transform_point3(frame.position(i, j, k))));
            }
        }
    }
    out
}

/// A solver's errors against a reference (DESIGN.md: relative RMSE of the composited image and
/// of the scattering grid).
#[derive(Clone, Copy, Debug)]
pub struct Errors {
    pub image: f64,
    pub grid: f64,
    /// Mean of the solver over mean of the reference, image and grid.
    pub image_ratio: f64,
    pub grid_ratio: f64,
    /// Error of the multiple-scattering part of the image alone, and its mean ratio; `None`
    /// against a fixture without the AOV.
    pub multiple: Option<f64>,
    pub multiple_ratio: Option<f64>,
}

/// "image E (xR), grid E (xR), multiple E (xR)": the line every solver's fixture test prints.
impl std::fmt::Display for Errors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "image {:.4} (x{:.3}), grid {:.4} (x{:.3}), multiple {:.4} (x{:.3})",
            self.image,
            self.image_ratio,
            self.grid,
            self.grid_ratio,
            self.multiple.unwrap_or(f64::NAN),
            self.multiple_ratio.unwrap_or(f64::NAN)
        )
    }
}

impl Errors {
    /// `image`, `grid` and `multiple` of a solver against those of the reference.
    pub fn between(image: &[Vec3], grid: &[Vec3], multiple: &[Vec3], ref_image: &[Vec3], ref_grid: &[Vec3], ref_multiple: Option<&[Vec3]>) -> Self {
        Errors {
            image: relative_rmse(image, ref_image),
            grid: relative_rmse(grid, ref_grid),
            image_ratio: mean(image) / mean(ref_image),
            grid_ratio: mean(grid) / mean(ref_grid),
            multiple: ref_multiple.map(|r| relative_rmse(multiple, r)),
            multiple_ratio: ref_multiple.map(|r| mean(multiple) / mean(r)),
        }
    }

    /// A solver's output against the fixture.
    pub fn against(out: &SolverOutput, fx: &Fixture) -> Self {
        assert_eq!(out.frame.dims, fx.grid_dims, "the fixture's grid is not this scene's FIXTURE_GRID frame");
        Errors::between(&out.image, &out.grid, &out.multiple, &fx.image(), &fx.grid(), fx.multiple().as_deref())
    }
}

/// The scattering grid of `scattering` compared with fixture `name` on scene `sc`.
pub fn errors_against_fixture(name: &str, sc: &Scene, scattering: &ScatteringGrid) -> Errors {
    Errors::against(&SolverOutput::of(sc, scattering), &load_fixture(name))
}

/// A homogeneous box of `n`^3 voxels of density 1, voxel size `voxel`, centred at the origin
/// (the analytic scenes: furnace, slab, the paper's Fig. 12 cube).
pub fn homogeneous_box(n: i32, voxel: f32, density_scale: f32, albedo: f32, g: f32) -> Medium {
    let vals = vec![1.0f32; (n * n * n) as usize];
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
    let to_world = Affine3A::from_translation(Vec3::splat(-(n as f32 - 1.0) * 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    Medium::new(grid, to_world, Vec3::splat(density_scale), Vec3::splat(albedo), g)
}

/// S / sigma_s (red channel) at the points of `grid` where the medium's density exceeds
/// `min_density`: 1 everywhere in a white furnace (uniform radiance 1, albedo 1), since the
/// phase function integrates to one against uniform radiance.
pub fn s_over_sigma_s(grid: &ScatteringGrid, medium: &Medium, min_density: f32) -> Vec<f32> {
    let mut ratios = Vec::new();
    for k in 0..grid.dims[2] {
        for j in 0..grid.dims[1] {
            for i in 0..grid.dims[0] {
                let dens = medium.density_world(grid.position(i, j, k));
                if dens > min_density {
                    ratios.push(grid.data[grid.index(i, j, k)].x / medium.sigma_s(dens).x);
                }
            }
        }
    }
    ratios
}

/// `errors_against_fixture` for a solver's output: how a ratchet row measures by default.
pub fn fixture_errors(case: &str, sc: &Scene, out: &SolveOutput) -> Errors {
    errors_against_fixture(case, sc, &out.scattering)
}

/// The ratchet against a converged reference, written once for every solver: solves fixture
/// `case`'s scene (`fixture_scene`) with `solver` through `Solver::solve` (one-off, CPU),
/// measures its errors with `measure` (`fixture_errors`, or a solver's own view of the same
/// comparison), prints them, and asserts the image and grid rel. RMSE bounds. `label` names the
/// row in what is printed and in the assertions' messages. Returns the errors and the output
/// (its report) for a row's further checks.
pub fn check_against_reference(
    label: &str,
    case: &str,
    solver: &dyn Solver,
    max_image: f64,
    max_grid: f64,
    measure: impl Fn(&str, &Scene, &SolveOutput) -> Errors,
) -> (Errors, SolveOutput) {
    let sc = fixture_scene(case);
    let t = std::time::Instant::now();
    let out = solver.solve(&sc, &mut SolveCtx::new(&NoProgress)).unwrap_or_else(|e| panic!("{label}: {} on {case}: {e}", solver.name()));
    let secs = t.elapsed().as_secs_f64();
    let e = measure(case, &sc, &out);
    eprintln!("{label} ({} on {case}): {e}; {secs:.1} s", solver.name());
    assert!(e.image <= max_image, "{label}: image rel. RMSE {:.4} over {max_image}", e.image);
    assert!(e.grid <= max_grid, "{label}: grid rel. RMSE {:.4} over {max_grid}", e.grid);
    (e, out)
}

/// Every solver's ratchets against the converged references, one `#[test]` per row:
///
/// ```text
/// against_reference! {
///     solver: "registry name";  // the rows' solver (asserted; coverage.rs lists the tables by it)
///     measure: f;   // optional: fn(case, &Scene, &SolveOutput) -> Errors (default `fixture_errors`)
///     then: g;      // optional: fn(case, &Errors, &SolveOutput), a row's further checks and prints
///     test_name: "fixture", solver, image bound, grid bound;
///     ...
/// }
/// ```
///
/// `solver` is an expression whose value implements `Solver`; each row runs
/// `check_against_reference`. Keep each row's measurement comment next to it.
#[cfg(test)]
macro_rules! against_reference {
    (solver: $name:literal; measure: $measure:expr; then: $then:expr; $($rows:tt)*) => {
        $crate::solvers::testing::against_reference!(@rows $name ($measure) ($then) $($rows)*);
    };
    (solver: $name:literal; measure: $measure:expr; $($rows:tt)*) => {
        $crate::solvers::testing::against_reference!(@rows $name ($measure) ($crate::solvers::testing::no_further_checks) $($rows)*);
    };
    (solver: $name:literal; then: $then:expr; $($rows:tt)*) => {
        $crate::solvers::testing::against_reference!(@rows $name ($crate::solvers::testing::fixture_errors) ($then) $($rows)*);
    };
    (@rows $name:literal ($measure:expr) ($then:expr) $($test:ident: $case:literal, $solver:expr, $image:expr, $grid:expr;)*) => {
        $(
            #[test]
            fn $test() {
                let solver = $solver;
                assert_eq!($crate::solvers::Solver::name(&solver), $name, "a row of the `against_reference!` table of {}", $name);
                let (e, out) = $crate::solvers::testing::check_against_reference(stringify!($test), $case, &solver, $image, $grid, $measure);
                ($then)($case, &e, &out);
            }
        )*
    };
    (solver: $name:literal; $($rows:tt)*) => {
        $crate::solvers::testing::against_reference!(@rows $name ($crate::solvers::testing::fixture_errors) ($crate::solvers::testing::no_further_checks) $($rows)*);
    };
}
#[cfg(test)]
pub(crate) use against_reference;

/// A ratchet row without further checks.
pub fn no_further_checks(_: &str, _: &Errors, _: &SolveOutput) {}
