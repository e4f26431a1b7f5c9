//! The compositor: ray-marches a scattering grid S with the medium's transmittance into an
//! RGBA image, the way a host renders S as volume emission with the medium's density for
//! extinction: L = integral T(0,t) S(x(t)) dt + T(0,inf) L_env(d), alpha = 1 - T.
//!
//! The medium's own emission seen directly, `integral T(0,t) e(x(t)) dt`, is part of the image
//! (Cycles' image of a flame holds its glow): S carries only the light the emission sends to
//! scattering points, so a host that renders the emission itself (Blender) takes S alone.
//!
//! AOVs, each only when asked for (`Aovs`): `single` (single scattering, computed here by ray
//! marching shadow rays, independent of the solver), `multiple` (the rest of S), `background`
//! (environment through the medium), `emission` (the emission seen directly). The first two need the single-scattering grid, which costs
//! more than the march itself: without them it is not computed at all.
//! Pixels use a box filter: `subpixels`^2 stratified rays each.
//!
//! `composite` (and the pipeline's, after either device's march) then makes the single
//! scattering of point and spot lamps exact near them, where no grid follows it
//! (`near_lamps`; `CompositeOptions::near_lamps`, the CLI's `--grid-only` to leave it out).

mod near_lamps;
/// At most this many lamps get the near-lamp pass (auto's time model counts them).
pub use near_lamps::MAX_LAMPS as NEAR_LAMPS_MAX;

use glam::{Affine3A, IVec3, Vec3, Vec4};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::image::Image;
use crate::medium::dense_march::Marcher;
use crate::medium::trilinear::{inside, trilinear_cell};
use crate::medium::{ray_box, Medium};
use crate::scene::Scene;
use crate::stages::single_scattering::{dome_directions_for, exp_neg, is_grey, single_scattering_grid, DOME_DIRECTIONS};
use crate::stages::ScatteringGrid;

/// The AOV layers an image carries besides RGBA, in this order when present.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Aovs {
    pub single: bool,
    pub multiple: bool,
    pub background: bool,
    pub emission: bool,
}

impl Aovs {
    pub const NONE: Aovs = Aovs { single: false, multiple: false, background: false, emission: false };
    pub const ALL: Aovs = Aovs { single: true, multiple: true, background: true, emission: true };
    /// The layer names, in image order.
    pub const NAMES: [&'static str; 4] = ["single", "multiple", "background", "emission"];

    /// Whether the single-scattering grid must be computed: `multiple` is the scattered light
    /// minus its single part, so it needs the grid as much as `single` does.
    pub fn needs_single(self) -> bool {
        self.single || self.multiple
    }

    /// A comma-separated list of layer names, or `all`, or `none` (or the empty string).
    pub fn parse(list: &str) -> Result<Aovs> {
        let mut aovs = Aovs::NONE;
        for name in list.split(',').map(str::trim).filter(|n| !n.is_empty()) {
            match name {
                "single" => aovs.single = true,
                "multiple" => aovs.multiple = true,
"background" => aovs.background = true,
                "emission" => aovs.emission = true,
                "all" => aovs = Aovs::ALL,
                "none" => {}
                other => {
                    return Err(Error::InvalidArgument(format!(
                        "unknown AOV `{other}` (AOVs: {}, or all, or none)",
                        Aovs::NAMES.join(", ")
                    )))
                }
            }
        }
        Ok(aovs)
    }

    /// Whether the layer `name` is in the set (unknown names are not).
    pub fn contains(self, name: &str) -> bool {
        match name {
            "single" => self.single,
            "multiple" => self.multiple,
            "background" => self.background,
            "emission" => self.emission,
            _ => false,
        }
    }
}

#[derive(Clone, Debug)]
pub struct CompositeOptions {
    pub transparent: bool,
    /// Sub-pixel rays per axis (box filter).
    pub subpixels: u32,
    /// March step as a fraction of the smallest voxel edge.
    pub step_voxels: f32,
    /// Largest dimension of the grid on which single scattering is computed for the AOV.
    pub single_resolution: u32,
    /// Directions used for the dome's single scattering (deterministic, importance-sampled): at
    /// most this many, fewer for a dim dome (`dome_directions_for`). 32: within 1.8% of 64 on
    /// the plume under sun and sky, at half the cost (the dome is nearly all of it).
    pub dome_directions: u32,
    /// The AOV layers to make. The library's default is every layer, so that code reading
    /// them keeps working; the image-making front ends (the CLI's `render --aov`, the C ABI's
    /// `vs_result_composite_aovs`, the hosts) pass only what was asked for.
    pub aovs: Aovs,
    /// The single scattering of point and spot lamps exact near them (`near_lamps`), not the
    /// grid's interpolation of it. Off: the image is the grid's march alone, as a host renders it.
    pub near_lamps: bool,
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions { transparent: false, subpixels: 2, step_voxels: 0.5, single_resolution: 48, dome_directions: DOME_DIRECTIONS, aovs: Aovs::ALL, near_lamps: true }
    }
}

/// A scattering grid's lookups along camera rays: the ray is carried into the grid's index
/// space once, and the cell found by truncation (no floorf call): the lookup is
/// `ScatteringGrid::sample_index`'s to the bit (floor is truncation inside the grid, where
/// coordinates are non-negative), at the march's sample points up to float rounding.
struct GridLookup<'a> {
    grid: &'a ScatteringGrid,
    world_to_index: Affine3A,
    dims: IVec3,
    /// The largest index coordinate (dims - 1): the lookup reads zero past it, or below 0.
    hi: Vec3,
}

impl<'a> GridLookup<'a> {
    fn new(grid: &'a ScatteringGrid) -> Self {
        let dims = IVec3::new(grid.dims[0] as i32, grid.dims[1] as i32, grid.dims[2] as i32);
        GridLookup { grid, world_to_index: grid.index_to_world.inverse(), dims, hi: (dims - IVec3::ONE).as_vec3() }
    }

    /// The world ray `o + t d` in index space: the same `t` reaches the same point.
    fn ray(&self, o: Vec3, d: Vec3) -> (Vec3, Vec3) {
        (self.world_to_index.transform_point3(o), self.world_to_index.transform_vector3(d))
    }

    #[inline]
    fn at_index(&self, p: Vec3) -> Vec3 {
        if !inside(p, Vec3::ZERO, self.hi) {
            return Vec3::ZERO;
        }
        if self.dims.min_element() < 2 {
            return self.grid.sample_index(p);
        }
        let (dims, data) = (self.dims, &self.grid.data);
        let i = p.as_ivec3().min(dims - IVec3::splat(2));
        trilinear_cell(i, p - i.as_vec3(), |c: IVec3| data[(c.x + dims.x * (c.y + dims.y * c.z)) as usize])
    }
}

/// What every camera ray of a composite shares: the medium's density as a dense copy (one per
/// composite), its box, and the S (and S1) lookups.
struct CameraMarch<'a> {
    medium: &'a Medium,
    density: Marcher<'a>,
    grey: bool,
    bounds: (Vec3, Vec3),
    s: GridLookup<'a>,
    s1: Option<GridLookup<'a>>,
    step: f32,
}

impl CameraMarch<'_> {
    /// Marches one camera ray. Without S1 (no AOV needs it) its integral is zero and it costs
    /// no lookups. The sample points are those of the world-space march (t0 + (i + 1/2) h),
    /// each grid's carried by its own index-space ray.
    fn march(&self, o: Vec3, d: Vec3) -> Marched {
        let Some((t0, t1)) = ray_box(o, d, self.bounds.0, self.bounds.1) else { return Marched { transmittance: Vec3::ONE, ..Default::default() } };
        let n = (((t1 - t0) / self.step).ceil() as u32).clamp(1, 8192);
        let h = (t1 - t0) / n as f32;
        let (dp, dd) = self.density.lattice_ray(o, d);
        let (sp, sd) = self.s.ray(o, d);
        let s1_ray = self.s1.as_ref().map(|s1| (s1, s1.ray(o, d)));
        let mut tr = Vec3::ONE;
        let mut l = Vec3::ZERO;
        let mut l1 = Vec3::ZERO;
        let mut le = Vec3::ZERO;
        let emission = self.medium.emission.as_ref();
        for i in 0..n {
            let t = t0 + (i as f32 + 0.5) * h;
            let (weight, seg_t) = step_weight(self.medium.sigma_t(self.density.density_lattice(dp + dd * t)), h, self.grey);
            l += tr * weight * self.s.at_index(sp + sd * t);
            if let Some((s1, (p1, d1))) = &s1_ray {
                l1 += tr * weight * s1.at_index(*p1 + *d1 * t);
            }
            if let Some(e) = emission {
                le += tr * weight * e.at(o + d * t);
            }
            tr *= seg_t;
            if tr.max_element() < 1e-5 {
                tr = Vec3::ZERO;
                break;
            }
        }
        Marched { scattered: l, single: l1, emitted: le, transmittance: tr }
    }
}

/// A march step of length `h` through constant `sigma_t`: the exact integral of T over it,
/// (1 - e^{-sigma h}) / sigma, by its series where sigma h is small (the difference would cancel
/// catastrophically), and the step's transmittance.
#[inline]
fn step_weight(sigma_t: Vec3, h: f32, grey: bool) -> (Vec3, Vec3) {
    let od = sigma_t * h;
    let seg_t = exp_neg(od, grey);
    let series = Vec3::splat(h) * (Vec3::ONE - od * 0.5 + od * od / 6.0);
    (Vec3::select(od.cmpgt(Vec3::splat(0.01)), (Vec3::ONE - seg_t) / sigma_t, series), seg_t)
}

/// What one camera ray's march gathered.
#[derive(Clone, Copy, Debug, Default)]
struct Marched {
    /// In-scattered radiance from S.
    scattered: Vec3,
    /// From the single-scattering grid S1 (zero without it).
    single: Vec3,
    /// The medium's emission.
    emitted: Vec3,
    transmittance: Vec3,
}

/// Renders the scattering grid `s` as seen by the scene's camera, with the AOVs `opts` asks for.
pub fn composite(scene: &Scene, s: &ScatteringGrid, opts: &CompositeOptions) -> Result<Image> {
    let single = single_for(scene, opts)?;
    let mut img = composite_with_single(scene, s, single.as_ref(), opts)?;
    add_near_lamps(scene, s, single.as_ref(), opts, &mut img);
    Ok(img)
}

/// Adds to an image of `s` (either compositor's) the lamps' exact single scattering near them
/// in place of the grid's (`near_lamps`), when `opts` asks for it and a lamp is near the medium.
pub fn add_near_lamps(scene: &Scene, s: &ScatteringGrid, single: Option<&ScatteringGrid>, opts: &CompositeOptions, img: &mut Image) {
    if !opts.near_lamps {
        return;
    }
    if let Some(lamps) = near_lamps::NearLamps::new(scene, s, single.filter(|_| opts.aovs.needs_single()), opts) {
        lamps.add_to(scene, img, opts.subpixels);
    }
}

/// The single-scattering grid `opts`' AOVs need, or None when none needs it (then it is not
/// computed at all: it costs more than the march). Its nodes are made for trilinear rendering
/// as the solvers' S is (lattice_product::finish), so that the `multiple` AOV, S less it, is
/// the multiple scattering's share alone.
pub fn single_for(scene: &Scene, opts: &CompositeOptions) -> Result<Option<ScatteringGrid>> {
    if !opts.aovs.needs_single() {
        return Ok(None);
    }
    let mut single = single_scattering_grid(scene, opts.single_resolution, dome_directions_for(scene, opts.dome_directions))?;
    crate::lattice_product::finish(&scene.medium, &mut single);
    Ok(Some(single))
}

/// `composite` with the single-scattering grid given (`single_for`'s), so that a caller can
/// time or place the two stages apart.
pub fn composite_with_single(scene: &Scene, s: &ScatteringGrid, single: Option<&ScatteringGrid>, opts: &CompositeOptions) -> Result<Image> {
    if opts.aovs.needs_single() && single.is_none() {
        return Err(Error::InvalidArgument("the single and multiple AOVs need the single-scattering grid".into()));
    }
    let medium = &scene.medium;
    let cam = &scene.camera;
    Image::check_budget(cam.width, cam.height, "composited image")?;
    let step = (medium.voxel_size_world().min_element() * opts.step_voxels.max(0.05)).max(1e-6);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let k = opts.subpixels.clamp(1, 16);
    // The emission may reach past the density's box (a flame in clear air).
    let bounds = match &medium.emission {
        Some(e) => {
            let (a, b) = (medium.world_bounds(), e.world_bounds());
            (a.0.min(b.0), a.1.max(b.1))
        }
        None => medium.world_bounds(),
    };
    // At most this many density lookups (every ray along the box's diagonal): what decides
    // whether the dense copy pays.
    let lookups = (w * h) as f64 * (k * k) as f64 * ((bounds.1 - bounds.0).length() / step).ceil().min(8192.0) as f64;
    let cm = CameraMarch {
        medium,
        density: Marcher::for_lookups(medium, lookups as u64),
        grey: is_grey(medium),
        bounds,
        s: GridLookup::new(s),
        s1: single.filter(|_| opts.aovs.needs_single()).map(GridLookup::new),
        step,
    };
    let env = scene.environment();
    let inv = 1.0 / (k * k) as f32;
    let pixels: Vec<Pixel> = (0..w * h)
        .into_par_iter()
        .map(|idx| {
            let (x, y) = ((idx % w) as f32, (idx / w) as f32);
            let (mut l, mut l1, mut le, mut bg, mut tsum) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
            for sy in 0..k {
                for sx in 0..k {
                    let d = cam.ray_dir(x + (sx as f32 + 0.5) / k as f32, y + (sy as f32 + 0.5) / k as f32);
                    let m = cm.march(cam.position, d);
                    let tr = m.transmittance;
                    l += m.scattered + m.emitted;
                    l1 += m.single;
                    le += m.emitted;
                    tsum += tr;
                    if let Some(env) = env {
                        bg += tr * env.radiance(d);
                    }
                }
            }
            let (l, tr) = (l * inv, tsum * inv);
            let alpha = 1.0 - tr.dot(Vec3::splat(1.0 / 3.0));
            let rgb = l + if opts.transparent { Vec3::ZERO } else { bg * inv };
            Pixel { rgba: rgb.extend(alpha.clamp(0.0, 1.0)), single: l1 * inv, background: bg * inv, emission: le * inv }
        })
        .collect();
    Ok(assemble_image(cam.width, cam.height, pixels, opts.transparent, opts.aovs))
}

/// One composited pixel and the parts its AOVs are made of.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pixel {
    pub rgba: Vec4,
    /// Single scattering (zero when no AOV needs it).
    pub single: Vec3,
    /// The environment through the medium (in `rgba` unless transparent).
    pub background: Vec3,
    /// The medium's emission seen directly (in `rgba`).
    pub emission: Vec3,
}

/// The image and the AOVs in `aovs` from its pixels in row order: `multiple` is what was
/// scattered minus its single part. Shared by the CPU and GPU compositors so that both define
/// the AOVs the same way.
pub fn assemble_image(width: u32, height: u32, pixels: impl IntoIterator<Item = Pixel>, transparent: bool, aovs: Aovs) -> Image {
    let n = width as usize * height as usize;
    let mut img = Image::new(width, height);
    let mut layers: [Vec<Vec3>; 4] = Default::default();
    for (name, layer) in Aovs::NAMES.iter().zip(&mut layers) {
        if aovs.contains(name) {
            layer.reserve_exact(n);
        }
    }
    for (i, p) in pixels.into_iter().take(n).enumerate() {
        img.rgba[i] = p.rgba;
        let scattered = p.rgba.truncate() - p.emission - if transparent { Vec3::ZERO } else { p.background };
        for (value, (name, layer)) in [p.single, scattered - p.single, p.background, p.emission].into_iter().zip(Aovs::NAMES.iter().zip(&mut layers)) {
            if aovs.contains(name) {
                layer.push(value);
            }
        }
    }
    img.aovs = Aovs::NAMES.iter().zip(layers).filter(|(name, _)| aovs.contains(name)).map(|(name, layer)| (name.to_string(), layer)).collect();
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Light;
    use crate::solvers::SolveCtx;
    use crate::solvers::Solver;
    use crate::stages::single_scattering::single_scattering_grid_dome_spaced;
    use crate::image::relative_rmse;
    use crate::solvers::reference::{Reference, ReferenceSettings};
    use crate::stages::{NoProgress, Timings};

    /// The dome interpolated from every second point (`single_scattering_grid_dome_spaced`)
    /// against the dome at every point, on the default scene (sun and sky, 64^3 grid): the
    /// grid's relative RMSE and its sum. Measured 0.012 and +0.06% (blended linearly, not as
    /// logarithms: 0.024 and +1.3%; the sun, marched at every
    /// point either way, carries the sharp shadows); bounds 0.03 and 0.5%. On a grid under
    /// `MIN_DOME_POINTS` coarse points it is the plain grid to the bit.
    #[test]
    fn dome_spacing_interpolates_the_sky() {
        let scene = Scene::default_scene();
        let full = single_scattering_grid(&scene, 64, 32).unwrap();
        let spaced = single_scattering_grid_dome_spaced(&scene, 64, 32, 2, &NoProgress).unwrap();
        let e = relative_rmse(&spaced.data, &full.data);
        let sum = |g: &ScatteringGrid| g.data.iter().map(|v| v.element_sum() as f64).sum::<f64>();
        let ratio = sum(&spaced) / sum(&full);
        eprintln!("dome spacing 2: relative RMSE {e:.4}, sum x{ratio:.5}");
        assert!(e < 0.03 && (ratio - 1.0).abs() < 0.005, "relative RMSE {e}, sum x{ratio}");
        let small = single_scattering_grid_dome_spaced(&scene, 48, 32, 2, &NoProgress).unwrap();
        assert_eq!(small.data, single_scattering_grid(&scene, 48, 32).unwrap().data);
    }

    fn small_default_scene(size: u32) -> Scene {
        let mut scene = Scene::default_scene();
        let c = scene.camera.clone();
        scene.camera = crate::scene::Camera::look_at(c.position, c.position + c.forward, c.up, c.fov_deg, size, size);
        scene
    }

    /// The compositor's single scattering of local lights (a spot, and a rect light as 8x8
    /// VPLs) against the path tracer's single-scattering AOV on the plume. Tolerance 15%, as
    /// for the default scene below: the reference AOV's noise at 256 spp is ~5-8% per pixel.
    #[test]
    fn single_scattering_of_spot_and_rect_matches_reference() {
        use crate::scene::{AreaLight, AreaShape, Light, Spot};
        let mut scene = small_default_scene(32);
        let cos_outer = 25f32.to_radians().cos();
        scene.lights = vec![
            Light::Spot(Spot { position: Vec3::new(-1.5, -1.0, 1.2), axis: Vec3::new(1.5, 1.0, -1.2).normalize(), intensity: Vec3::new(6.0, 5.0, 4.0), radius: 0.0, cos_outer, cos_inner: cos_outer + 0.3 * (1.0 - cos_outer) }),
            Light::Area(AreaLight { center: Vec3::new(1.3, 0.0, 0.2), normal: -Vec3::X, tangent: Vec3::Y, shape: AreaShape::Rect { width: 0.8, height: 0.5 }, radiance: Vec3::new(1.0, 2.0, 3.0) }),
        ];
        let r = Reference::new(ReferenceSettings { spp: 256, ..Default::default() }).unwrap();
        let img = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut Timings::default()).expect("the reference renders images").unwrap();
        let zero = ScatteringGrid::over_medium(&scene.medium, 8).unwrap();
        let comp = composite(&scene, &zero, &CompositeOptions::default()).unwrap();
        let e1 = relative_rmse(comp.aov("single").unwrap(), img.aov("single").unwrap());
        assert!(e1 < 0.15, "single-scattering AOV: {e1}");
    }

    /// The dome's share of the light sets its directions: the default scene's sky (a third of
    /// the unshadowed light beside its sun) gets all of them, the same sky at a tenth of its
    /// radiance fewer in proportion, and never under 8.
    #[test]
    fn dim_dome_gets_fewer_directions() {
        let mut scene = Scene::default_scene();
        assert_eq!(dome_directions_for(&scene, 32), 32);
        let dim_by = |scene: &mut Scene, k: f32| {
            for light in &mut scene.lights {
                if let Light::Dome(dome) = light {
                    dome.color *= k;
                }
            }
        };
        dim_by(&mut scene, 0.1);
        let dim = dome_directions_for(&scene, 32);
        assert!((8..=16).contains(&dim), "dim dome: {dim} directions");
        dim_by(&mut scene, 1e-3);
        assert_eq!(dome_directions_for(&scene, 32), 8);
    }

    /// Without the single and multiple AOVs the image has only the layers asked for and its
    /// RGBA is that of the full composite (the AOVs never feed the beauty); `single` alone
    /// equals the full composite's.
    #[test]
    fn aovs_are_made_only_when_asked() {
        let scene = small_default_scene(12);
        let mut s = ScatteringGrid::over_medium(&scene.medium, 12).unwrap();
        s.data.iter_mut().enumerate().for_each(|(i, v)| *v = Vec3::splat((i % 5) as f32 * 0.1));
        let all = composite(&scene, &s, &CompositeOptions::default()).unwrap();
        let names = |img: &Image| img.aovs.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        assert_eq!(names(&all), ["single", "multiple", "background", "emission"]);
        let none = composite(&scene, &s, &CompositeOptions { aovs: Aovs::NONE, ..Default::default() }).unwrap();
        assert!(none.aovs.is_empty());
        assert_eq!(none.rgba, all.rgba);
        let single = composite(&scene, &s, &CompositeOptions { aovs: Aovs { single: true, ..Aovs::NONE }, ..Default::default() }).unwrap();
        assert_eq!(names(&single), ["single"]);
        assert_eq!(single.aov("single"), all.aov("single"));
        assert_eq!(Aovs::parse("background, single").unwrap(), Aovs { single: true, multiple: false, background: true, emission: false });
        assert_eq!(Aovs::parse("all").unwrap(), Aovs::ALL);
        assert_eq!(Aovs::parse("none").unwrap(), Aovs::NONE);
        assert!(Aovs::parse("singel").unwrap_err().to_string().contains("singel"));
    }

    /// A grey slab seen head-on with S = 0: the alpha is 1 - exp(-sigma_t d) to quadrature
    /// accuracy, whatever the step.
    #[test]
    fn transmittance_of_homogeneous_box_is_exact() {
        let medium = crate::solvers::reference::tests::homogeneous_box(8, 0.1, 3.0, 0.5, 0.0);
        let scene = Scene {
            medium,
            lights: vec![],
            camera: crate::scene::Camera::look_at(Vec3::new(0.0, -3.0, 0.0), Vec3::ZERO, Vec3::Z, 1.0, 3, 3),
            solver: Default::default(),
        };
        let zero = ScatteringGrid::over_medium(&scene.medium, 8).unwrap();
        let img = composite(&scene, &zero, &CompositeOptions::default()).unwrap();
        let expected = 1.0 - (-3.0f32 * 0.8).exp();
        assert!((img.rgba[4].w - expected).abs() < 1e-3, "{} vs {expected}", img.rgba[4].w);
        assert_eq!(img.rgba[4].truncate(), Vec3::ZERO);
    }

    /// The reference's own scattering grid, composited, must reproduce the reference's
    /// path-traced image: this checks the compositor and the S estimator against each other.
    /// Tolerance 12%: the grid is coarse (32^3 over a 64^3 plume), which blurs S at the
    /// plume's edges, plus the Monte Carlo noise of both (each ~2-3%).
    #[test]
    fn composited_reference_grid_matches_path_traced_image() {
        let scene = small_default_scene(32);
        let r = Reference::new(ReferenceSettings { spp: 256, grid_resolution: 32, grid_spp: 64, ..Default::default() }).unwrap();
        let mut t = Timings::default();
        let img = r.render_image(&scene, &mut SolveCtx::new(&NoProgress), false, &mut t).expect("the reference renders images").unwrap();
        let grid = r.scattering_grid(&scene, &NoProgress, &mut t).unwrap();
        let comp = composite(&scene, &grid, &CompositeOptions::default()).unwrap();
        let a: Vec<Vec3> = comp.rgba.iter().map(|p| p.truncate()).collect();
        let b: Vec<Vec3> = img.rgba.iter().map(|p| p.truncate()).collect();
        let e = relative_rmse(&a, &b);
        assert!(e < 0.12, "relative RMSE composited vs path traced: {e}");
        // The single-scattering AOVs agree too (the compositor's is deterministic).
        let e1 = relative_rmse(comp.aov("single").unwrap(), img.aov("single").unwrap());
        assert!(e1 < 0.15, "single-scattering AOV: {e1}");
        // Alpha: exact in the compositor, ratio-tracked in the path tracer.
        let da: f32 = comp.rgba.iter().zip(&img.rgba).map(|(p, q)| (p.w - q.w).abs()).sum::<f32>() / img.rgba.len() as f32;
        assert!(da < 0.01, "mean alpha difference {da}");
    }
}
