//! Test-only harness shared by every solver's tests (compiled under `cfg(test)` only): the
//! converged reference fixtures in `fixtures/` (image + scattering grid + their own noise), the
//! metrics every solver is measured by against them (DESIGN.md "Engineering rules"), and the
//! checks written once and run over every solver (white furnace, energy balance: furnace.rs),
//! plus the dense-cloud fixture (cloud.rs).

pub(crate) mod cloud;
mod furnace;

use crate::solvers::SolveCtx;
use crate::solvers::Solver;
use glam::{Affine3A, IVec3, Vec3};

use crate::compositor::{composite, CompositeOptions};
use crate::image::{relative_rmse, Image};
use crate::medium::{DensityGrid, GridLimits, Medium};
use crate::scene::Scene;
use crate::solvers::reference::{Reference, ReferenceSettings};
use crate::stages::{NoProgress, ScatteringGrid, Timings};

/// Resolution (largest dimension) of the fixtures' scattering grids, on which every solver's
/// grid is compared: coarse, so that the reference converges per grid point in minutes.
pub(crate) const FIXTURE_GRID: u32 = 10;

/// A converged reference solution, computed once by a `regenerate_*` test (`#[ignore]`d: the
/// path tracer needs minutes for these, the solvers' tests must run in seconds) and stored as
/// `fixtures/<name>.json`.
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct Fixture {
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

pub(crate) fn fixture_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/solvers/fixtures").join(format!("{name}.json"))
}

pub(crate) fn load_fixture(name: &str) -> Fixture {
    let text = std::fs::read_to_string(fixture_path(name))
        .unwrap_or_else(|e| panic!("fixture {name} missing ({e}): run its `regenerate_*` test with --run-ignored only"));
    serde_json::from_str(&text).unwrap()
}

/// An unsigned setting of a `regenerate_*` / `explore*` test from the environment.
/// The scene of any shared fixture by name: the dense cloud, the local-light cases
/// (`plume_*`, `fig10_*`, pop/radial/tests.rs), the dome cases (`dome_*`) and the distant-light
/// cases (pop/tests.rs).
pub(crate) fn fixture_scene(name: &str) -> Scene {
    if name == "cloud" {
        cloud::cloud_scene()
    } else if name.starts_with("dome_") {
        crate::solvers::pop::tests::dome_cases::dome_case(name)
    } else if name.starts_with("plume_") || name.starts_with("fig10") {
        crate::solvers::pop::radial::tests::case(name)
    } else {
        crate::solvers::pop::tests::case(name)
    }
}

/// A host that has cancelled: every progress callback answers stop.
pub(crate) struct Cancelled;

impl crate::stages::Progress for Cancelled {
    fn update(&self, _: &str, _: f32) -> bool {
        false
    }
    fn cancelled(&self) -> bool {
        true
    }
}

pub(crate) fn env_u32(key: &str, default: u32) -> u32 {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The cases whose name contains the environment variable `key` (all when it is unset).
pub(crate) fn selected<'a>(cases: &'a [&'a str], key: &str) -> impl Iterator<Item = &'a str> + 'a {
    let only = std::env::var(key).unwrap_or_default();
    cases.iter().copied().filter(move |n| only.is_empty() || n.contains(only.as_str()))
}

/// Renders `sc` with the reference path tracer in two independent halves (seeds 1 and 2) of
/// `spp` paths per pixel and `grid_spp` per grid point (on a `FIXTURE_GRID` grid), and stores
/// their mean as the fixture `name`, with its noise from their difference.
pub(crate) fn regenerate_fixture(name: &str, sc: &Scene, spp: u32, grid_spp: u32) -> Fixture {
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
pub(crate) fn regenerate_selected(cases: &[&str], select_key: &str, case: impl Fn(&str) -> Scene, spp: u32, grid_spp: u32) {
    for name in selected(cases, select_key) {
        regenerate_fixture(name, &case(name), spp, grid_spp);
    }
}

/// A solver's composite against the compositor's own single-scattering AOV of the same image
/// (rel. RMSE, mean ratio): with a tiny albedo a solver's S is its single scattering, which the
/// compositor computes independently (ray-marched shadow rays).
pub(crate) fn against_single_scattering(sc: &Scene, scattering: &ScatteringGrid) -> (f64, f64) {
    let img = composite(sc, scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
    let (image, single) = (rgb(&img), img.aov("single").unwrap());
    (relative_rmse(&image, single), mean(&image) / mean(single))
}

/// The RGB of an image, without alpha.
pub(crate) fn rgb(img: &Image) -> Vec<Vec3> {
    img.rgba.iter().map(|p| p.truncate()).collect()
}

pub(crate) fn vecs(v: &[[f32; 3]]) -> Vec<Vec3> {
    v.iter().map(|a| Vec3::from(*a)).collect()
}

/// Mean of the channel sums (so ratios of means weigh R, G, B alike).
pub(crate) fn mean(v: &[Vec3]) -> f64 {
    v.iter().map(|p| p.x as f64 + p.y as f64 + p.z as f64).sum::<f64>() / v.len().max(1) as f64
}

/// What a solver's scattering grid gives, in the fixtures' terms: the composited image (RGB,
/// transparent background), its multiple-scattering part (image minus the compositor's
/// single-scattering AOV, which the compositor computes the same way for every solver) and the
/// grid resampled (trilinear) onto the fixtures' `FIXTURE_GRID` frame.
pub(crate) struct SolverOutput {
    pub image: Vec<Vec3>,
    pub multiple: Vec<Vec3>,
    pub frame: ScatteringGrid,
    pub grid: Vec<Vec3>,
}

impl SolverOutput {
    pub fn of(sc: &Scene, scattering: &ScatteringGrid) -> Self {
        let img = composite(sc, scattering, &CompositeOptions { transparent: true, ..Default::default() }).unwrap();
        let image = rgb(&img);
        let multiple = image.iter().zip(img.aov("single").unwrap()).map(|(a, b)| *a - *b).collect();
        let frame = ScatteringGrid::over_medium(&sc.medium, FIXTURE_GRID).unwrap();
        let grid = resample(scattering, &frame);
        SolverOutput { image, multiple, frame, grid }
    }
}

/// `grid` looked up (trilinear, zero outside) at every point of `frame`, in `frame`'s order.
pub(crate) fn resample(grid: &ScatteringGrid, frame: &ScatteringGrid) -> Vec<Vec3> {
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
pub(crate) struct Errors {
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
pub(crate) fn errors_against_fixture(name: &str, sc: &Scene, scattering: &ScatteringGrid) -> Errors {
    Errors::against(&SolverOutput::of(sc, scattering), &load_fixture(name))
}

/// A homogeneous box of `n`^3 voxels of density 1, voxel size `voxel`, centred at the origin
/// (the analytic scenes: furnace, slab, the paper's Fig. 12 cube).
pub(crate) fn homogeneous_box(n: i32, voxel: f32, density_scale: f32, albedo: f32, g: f32) -> Medium {
    let vals = vec![1.0f32; (n * n * n) as usize];
    let grid = DensityGrid::from_dense(IVec3::ZERO, IVec3::splat(n), &vals, GridLimits::default()).unwrap();
    let to_world = Affine3A::from_translation(Vec3::splat(-(n as f32 - 1.0) * 0.5 * voxel)) * Affine3A::from_scale(Vec3::splat(voxel));
    Medium::new(grid, to_world, Vec3::splat(density_scale), Vec3::splat(albedo), g)
}

/// S / sigma_s (red channel) at the points of `grid` where the medium's density exceeds
/// `min_density`: 1 everywhere in a white furnace (uniform radiance 1, albedo 1), since the
/// phase function integrates to one against uniform radiance.
pub(crate) fn s_over_sigma_s(grid: &ScatteringGrid, medium: &Medium, min_density: f32) -> Vec<f32> {
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
