//! The one table of solvers: for each its name, one line of help, its settings (type, range,
//! help; the defaults are read from the settings struct's `Default`, so they cannot drift), the
//! light types it handles, the hosts' quality presets, its CPU constructor and whether a GPU
//! backend exists (volscatter-gpu dispatches on that flag). The CLI (`volscatter solvers`,
//! `render`, `compare`), the C ABI (`vs_solvers_json`) and the hosts (Blender add-on, USD) read
//! it, in Rust or as the JSON of `to_json`.
//!
//! Adding a solver is one `SolverEntry` in `SOLVERS`; the tests below check its settings table
//! against its struct (keys, types, defaults, every range check of `validate()`) and its presets
//! against its constructor.

use serde::Serialize;
use serde_json::{Map, Value};

use super::{lpm, network, photon_grid, pop, reference, vpl, Solver};
use crate::pipeline::auto;
use crate::error::{Error, Result};

/// A light type of the scene JSON (`lights[].type`, plus `emission` for an emissive medium),
/// named as there so that hosts can compare their exported scenes with a solver's list.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightType {
    Distant,
    /// A point light, or a sphere light when its `radius` > 0.
    Point,
    Spot,
    Rect,
    Disk,
    Dome,
    /// The medium's own emission (`medium.emission`).
    Emission,
}

impl LightType {
    pub const ALL: [LightType; 7] =
        [LightType::Distant, LightType::Point, LightType::Spot, LightType::Rect, LightType::Disk, LightType::Dome, LightType::Emission];

    pub fn name(self) -> &'static str {
        match self {
            LightType::Distant => "distant",
            LightType::Point => "point",
            LightType::Spot => "spot",
            LightType::Rect => "rect",
            LightType::Disk => "disk",
            LightType::Dome => "dome",
            LightType::Emission => "emission",
        }
    }

    pub fn help(self) -> &'static str {
        match self {
            LightType::Distant => "distant light (sun), optionally with an angular diameter",
            LightType::Point => "point light, or sphere light with a radius",
            LightType::Spot => "spot light (point or sphere with a cone)",
            LightType::Rect => "one-sided rectangle of uniform radiance",
            LightType::Disk => "one-sided disc of uniform radiance",
            LightType::Dome => "environment: uniform colour or lat-long texture",
            LightType::Emission => "emissive medium (medium.emission)",
        }
    }
}

/// The JSON type of a setting's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SettingType {
    /// A non-negative integer.
    Int,
    Float,
    Bool,
    /// One string of `choices`.
    Choice,
}

/// The values `validate()` accepts: [min, max], each end open when marked exclusive, an end
/// absent when unbounded (an `Int` is never below 0).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Range {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    #[serde(skip_serializing_if = "is_false")]
    pub min_exclusive: bool,
    #[serde(skip_serializing_if = "is_false")]
    pub max_exclusive: bool,
}

fn is_false(b: &bool) -> bool {
    !*b
}

impl Range {
    /// [min, max], both ends included.
    pub const fn closed(min: f64, max: f64) -> Range {
        Range { min: Some(min), max: Some(max), min_exclusive: false, max_exclusive: false }
    }

    /// Whether `v` lies in the range.
    pub fn contains(&self, v: f64) -> bool {
        let above = match self.min {
            Some(m) if self.min_exclusive => v > m,
            Some(m) => v >= m,
            None => true,
        };
        let below = match self.max {
            Some(m) if self.max_exclusive => v < m,
            Some(m) => v <= m,
            None => true,
        };
        above && below
    }
}

/// One setting of a solver, as the `solver` block of the scene JSON and `--set` name it.
#[derive(Clone, Copy, Debug)]
pub struct SettingSpec {
    pub name: &'static str,
    pub kind: SettingType,
    pub range: Option<Range>,
    /// When 0 is accepted outside `range` and stands for a value derived from other settings:
    /// what it stands for.
    pub zero: Option<&'static str>,
    /// For `Choice`: the accepted strings.
    pub choices: &'static [&'static str],
    pub help: &'static str,
}

impl SettingSpec {
    const fn new(name: &'static str, kind: SettingType, help: &'static str) -> Self {
        SettingSpec { name, kind, range: None, zero: None, choices: &[], help }
    }
    const fn range(mut self, min: f64, max: f64) -> Self {
        self.range = Some(Range::closed(min, max));
        self
    }
    const fn open_range(mut self, range: Range) -> Self {
        self.range = Some(range);
        self
    }
    const fn zero(mut self, means: &'static str) -> Self {
        self.zero = Some(means);
        self
    }
    const fn int(name: &'static str, help: &'static str) -> Self {
        SettingSpec::new(name, SettingType::Int, help)
    }
    const fn float(name: &'static str, help: &'static str) -> Self {
        SettingSpec::new(name, SettingType::Float, help)
    }
    const fn bool(name: &'static str, help: &'static str) -> Self {
        SettingSpec::new(name, SettingType::Bool, help)
    }
}

/// Named settings a host offers as one choice (the Blender add-on's Quality menu). Values not
/// named keep the solver's defaults.
#[derive(Clone, Copy, Debug)]
pub struct Preset {
    pub name: &'static str,
    pub help: &'static str,
    /// A JSON object of settings (checked against the constructor by a test).
    pub settings_json: &'static str,
}

impl Preset {
    pub fn settings(&self) -> Map<String, Value> {
        match serde_json::from_str(self.settings_json) {
            Ok(Value::Object(m)) => m,
            // The registry's own tests parse every preset: unreachable in a tested build.
            _ => Map::new(),
        }
    }
}

/// Builds a CPU solver from a `solver` settings block.
pub type CpuConstructor = fn(&Map<String, Value>) -> Result<Box<dyn Solver>>;

/// What a registry name stands for.
#[derive(Clone, Copy)]
pub enum Make {
    /// A solver, built from its settings (validated; unknown keys refused).
    Solver(CpuConstructor),
    /// A pick among the solvers per scene (`auto`, resolved by the pipeline); the function
    /// validates its settings.
    Picker(fn(&Map<String, Value>) -> Result<()>),
}

/// One solver.
#[derive(Clone, Copy)]
pub struct SolverEntry {
    pub name: &'static str,
    /// The name in hosts' menus.
    pub label: &'static str,
    pub help: &'static str,
    pub settings: &'static [SettingSpec],
    /// The settings struct's `Default`, serialised (the defaults the registry reports).
    pub defaults: fn() -> Value,
    pub lights: &'static [LightType],
    pub presets: &'static [Preset],
    /// The solver (or the picker) this name builds.
    pub make: Make,
    /// Whether volscatter-gpu has a backend for it (its dispatch table is tested against this).
    pub gpu: bool,
}

impl SolverEntry {
    /// Checks `settings` as building would (unknown keys and values out of range refused).
    pub fn validate(&self, settings: &Map<String, Value>) -> Result<()> {
        match self.make {
            Make::Solver(build) => build(settings).map(drop),
            Make::Picker(validate) => validate(settings),
        }
    }

    /// The solver with `settings`; a picker (`auto`) is refused: it names no solver until it
    /// sees a scene (`pipeline::Session` resolves it).
    pub fn build(&self, settings: &Map<String, Value>) -> Result<Box<dyn Solver>> {
        match self.make {
            Make::Solver(build) => build(settings),
            Make::Picker(validate) => {
                validate(settings)?;
                Err(Error::InvalidArgument(format!("`{}` picks a solver for each scene: solve through the pipeline (pipeline::Session)", self.name)))
            }
        }
    }

    pub fn handles(&self, light: LightType) -> bool {
        self.lights.contains(&light)
    }

    pub fn preset(&self, name: &str) -> Option<&'static Preset> {
        self.presets.iter().find(|p| p.name == name)
    }

    /// The JSON form: name, label, help, gpu, lights, settings (with defaults), presets.
    pub fn to_json(&self) -> Value {
        let defaults = (self.defaults)();
        let settings: Vec<Value> = self
            .settings
            .iter()
            .map(|s| {
                let mut m = Map::new();
                m.insert("name".into(), s.name.into());
                m.insert("type".into(), serde_json::to_value(s.kind).unwrap_or(Value::Null));
                m.insert("default".into(), defaults.get(s.name).cloned().unwrap_or(Value::Null));
                if let Some(r) = s.range {
                    m.insert("range".into(), serde_json::to_value(r).unwrap_or(Value::Null));
                }
                if let Some(z) = s.zero {
                    m.insert("zero".into(), z.into());
                }
                if !s.choices.is_empty() {
                    m.insert("choices".into(), s.choices.into());
                }
                m.insert("help".into(), s.help.into());
                Value::Object(m)
            })
            .collect();
        let presets: Vec<Value> =
            self.presets.iter().map(|p| serde_json::json!({"name": p.name, "help": p.help, "settings": p.settings()})).collect();
        serde_json::json!({
            "name": self.name,
            "label": self.label,
            "help": self.help,
            "gpu": self.gpu,
            "lights": self.lights,
            "settings": settings,
            "presets": presets,
        })
    }
}

/// The hosts' quality presets (the Blender add-on's Draft / Preview / Final).
const DRAFT: &str = "coarse grids, few iterations or samples";
const PREVIEW: &str = "the interactive default";
const FINAL: &str = "fine grids, many iterations or samples";

const REFERENCE: SolverEntry = SolverEntry {
    name: "reference",
    label: "Reference",
    help: "unbiased volumetric path tracer (slow, the ground truth)",
    settings: &[
        SettingSpec::int("spp", "samples per pixel for images").range(1.0, (1u32 << 20) as f64),
        SettingSpec::int("seed", "random seed (deterministic for a seed, any thread count)"),
        SettingSpec::int("max_depth", "most scattering events on a path"),
        SettingSpec::int("rr_depth", "scattering events before Russian roulette starts"),
        SettingSpec::bool("transparent", "leave the environment seen directly through the medium out of the image"),
        SettingSpec::int("grid_resolution", "largest side of the scattering grid").range(2.0, 1024.0),
        SettingSpec::int("grid_spp", "paths per scattering-grid point").range(1.0, (1u32 << 20) as f64),
        SettingSpec::int("output_resolution", "largest side of the returned grid, on the medium's voxels: sigma_s of each voxel times the radiance interpolated from the path grid")
            .range(2.0, 1024.0)
            .zero("the path grid itself, S point-sampled there"),
        SettingSpec::int("majorant_resolution", "cells per axis of the majorant grid used for free-flight sampling").range(1.0, 512.0),
    ],
    defaults: || serde_json::to_value(reference::ReferenceSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"grid_resolution": 16, "grid_spp": 16, "output_resolution": 64}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"grid_resolution": 32, "grid_spp": 64, "output_resolution": 128}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"grid_resolution": 64, "grid_spp": 256, "output_resolution": 256}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(reference::Reference::from_settings(m)?))),
    gpu: false,
};

const POP: SolverEntry = SolverEntry {
    name: "pop",
    label: "Principal Ordinates",
    help: "principal-ordinates propagation (paper 01), grids aligned with each light: 0.17-0.40 image error on smoke and cubes; dense clouds (optical depth 30+) 0.49 and 35% too dark, 0.25 with moment_anisotropy. Benchmark scenes (BENCHMARKS.md solvers, image rel. RMSE at preview, 1-16 s on 2 cores): thin smoke and overcast 0.09, fire-lit smoke 0.23, lamp inside smoke 0.50, dense cloud 0.71; final is slower and no better (0.13 on the smokes)",
    settings: &[
        SettingSpec::int("grid_resolution", "cells along the longest side of each light's propagation grid").range(2.0, 512.0),
        SettingSpec::int("max_iterations", "cap on propagation iterations per light").range(1.0, 100_000.0),
        SettingSpec::float("residual_threshold", "stop when the travelling energy falls below this fraction of the scattered")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: false, max_exclusive: true }),
        SettingSpec::int("merge_resolution", "largest side of the medium-aligned grid the lights are merged into")
            .range(2.0, 1024.0)
            .zero("twice grid_resolution"),
        SettingSpec::int("output_resolution", "largest side of the returned scattering grid").range(2.0, 1024.0),
        SettingSpec::bool("upsample", "joint bilateral upsampling guided by the density (off: trilinear)"),
        SettingSpec::float("range_sigma", "range sigma of the bilateral filter, a fraction of the largest density")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("spatial_sigma", "spatial sigma of the bilateral filter, in merged-grid cells")
            .open_range(Range { min: Some(0.0), max: Some(4.0), min_exclusive: true, max_exclusive: false }),
        SettingSpec::bool("diffusion_correction", "match the lattice's diffusion to the physical one where light is isotropic"),
        SettingSpec::bool("vacuum_escape", "isotropic light leaving the medium escapes instead of random-walking back"),
        SettingSpec::bool("moment_anisotropy", "each part of a lobe keeps its own mean cosine; empty cells re-emit isotropically (dense clouds: image 0.49 -> 0.25, flux 0.65x -> 1.02x; cube g 0.7 0.25 -> 0.30; CPU only)"),
        SettingSpec::int("dome_ordinates", "distant ordinates a dome is approximated by (0: the dome is left out)").range(0.0, 1024.0),
        SettingSpec::int("dome_grid_resolution", "propagation grid resolution of each dome ordinate")
            .range(2.0, 512.0)
            .zero("half of grid_resolution, at least 8"),
        SettingSpec::bool("dome_importance", "place the dome's ordinates by how much of their light reaches the camera"),
        SettingSpec::bool("isotropic_residuum", "finish nearly isotropic light in one shared isotropic grid"),
        SettingSpec::float("residuum_anisotropy", "anisotropy below which light counts as isotropic")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: true, max_exclusive: true }),
        SettingSpec::int("residuum_iterations", "iterations per light before the residuum takes over").zero("Eq. 10 per light"),
        SettingSpec::int("residuum_grid_resolution", "cells along the longest side of the residuum grid")
            .range(2.0, 512.0)
            .zero("dome_grid_resolution"),
        SettingSpec::int("radial_resolution", "angular cells per side of each local light's octahedral grid (even)")
            .range(4.0, 256.0)
            .zero("grid_resolution"),
        SettingSpec::int("radial_max_shells", "most shells per radial grid").range(1.0, 1024.0),
        SettingSpec::int("area_vpls", "an area light becomes area_vpls x area_vpls VPLs").range(1.0, 16.0),
        SettingSpec::int("emission_vpls", "VPLs an emissive medium becomes").range(1.0, 256.0),
        SettingSpec::bool("radial_vacuum_escape", "vacuum_escape for the local lights' radial grids"),
    ],
    defaults: || serde_json::to_value(pop::PopSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"grid_resolution": 16, "max_iterations": 100, "output_resolution": 64}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"grid_resolution": 32, "max_iterations": 400, "output_resolution": 128}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"grid_resolution": 64, "max_iterations": 1000, "output_resolution": 256}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(pop::Pop::from_settings(m)?))),
    gpu: true,
};

const VPL: SolverEntry = SolverEntry {
    name: "vpl",
    label: "Virtual Point Lights",
    help: "instant multiple scattering with virtual point lights (paper 03): random walks, exact single scattering, VPLs gathered on a coarse grid (near_field auto: the ball kernel on thin media, the attenuated top hat, lossless at any optical thickness, on media in which light scatters many times; the paper's clamp with bias compensation as an option: white furnace within 1%), the multiple scattering's power normalized to the walks', the ball's phase lobes smoothed below a quarter cell, transmittance from per-point depth maps. At the defaults the mean of 8 seeds is within 2% of the reference's flux on the cubes, the plume, the spot, the point light (32768 walks) and the rect light (131072 walks; x0.970 at 32768: the coarse gather's heavy-tailed estimate needs the walks), and on the dense cloud with the hat (32768 walks, x0.998; the ball's x1.080 spread 10% by seed). Fixture image rel. RMSE at 4096 walks: cubes 0.07-0.15, plume 0.33, local lights 0.09-0.15, dense cloud 0.42 (0.71 with the ball). At host sizes (BENCHMARKS.md vpl-image, 2 cores) 5% image error on the default scene in 0.65 s, 34x below the path tracer's time (point light beside the plume 96x), with the far VPLs as clusters of a gather cell (cluster_distance) and the sky's single scattering on every second point (dome_spacing). Benchmark scenes at preview (BENCHMARKS.md solvers, 2 cores): thin smoke 0.068 in 0.9 s, overcast 0.053, fire-lit smoke 0.097, lamp inside smoke 0.43, dense cloud 0.27 (final 0.32; with the ball kernel 0.34 and 0.61)",
    settings: &[
        SettingSpec::int("walks", "random walks from the lights (noise falls as 1/sqrt)").range(1.0, (1u32 << 24) as f64),
        SettingSpec::int("max_vertices", "most VPLs one walk leaves before it is cut").range(1.0, (1u32 << 20) as f64),
        SettingSpec::int("rr_depth", "scattering vertices before Russian roulette starts"),
        SettingSpec::int("walks_per_subset", "walks per interleaved subset gathered at each point").zero("every point uses every walk"),
        SettingSpec { choices: &["auto", "clamp", "ball", "hat", "compensate"], ..SettingSpec::new("near_field", SettingType::Choice, "near field of 1/d^2: auto (default: the hat in a medium in which light scatters many times, as a dense cloud: optical size over 0.9; the ball elsewhere), clamp at the radius, the lossless ball kernel (as good or better at equal cost on every thin fixture), the attenuated top hat (lossless at any optical thickness: dense cloud 8 seeds x0.998, image error 0.19 at 32768 walks against the ball's 0.5), or the clamp with bias compensation (right in a white furnace, heavy-tailed on thin smoke)") },
        SettingSpec::int("compensation_vertices", "compensation: new vertices per gather point").range(1.0, 256.0),
        SettingSpec::int("compensation_depth", "compensation: recursion levels (the last takes the VPLs with the ball kernel)").range(1.0, 8.0),
        SettingSpec::int("compensation_walks", "compensation: walks each new vertex connects to").range(1.0, (1u32 << 24) as f64),
        SettingSpec::float("clamp_radius", "near-field radius, in gather-cell radii")
            .open_range(Range { min: Some(0.0), max: Some(16.0), min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("mean_free_paths", "the ball kernel's radius is at most this many local mean free paths (0: no limit)")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: false, max_exclusive: false }),
        SettingSpec::float("phase_cone", "ball kernel: radius, in gather-cell radii, below which both phase functions are smoothed to the ball's cone (0: off); removes the dense cloud's heavy tail (8 seeds x1.40 +- 0.83 -> x0.97 +- 0.07)")
            .open_range(Range { min: Some(0.0), max: Some(16.0), min_exclusive: false, max_exclusive: false }),
        SettingSpec::bool("normalize_energy", "scale the multiple scattering so that the power it scatters equals the walks' (the coarse gather's global bias: point light beside the plume x0.878 -> x0.926, default scene image error 0.176 -> 0.146); not with compensate, near_refine or near_upsample ratio"),
        SettingSpec { choices: &["map", "march"], ..SettingSpec::new("transmittance", SettingType::Choice, "how the gather gets each connection's transmittance: a per-point directional optical-depth map looked up beyond one gather cell (default: default scene 16384 walks gather 3.0 -> 0.55 s, image error 0.0869 both; every fixture's error within 0.001) or a ray march to every VPL (the GPU always marches)") },
        SettingSpec::int("map_resolution", "transmittance map: n x n directions per gather point (default 8: the default scene's gather 0.25 -> 0.15 s against 16 at the same image error; 32: more exact, ~2x the map's cost)").range(2.0, 64.0),
        SettingSpec::float("cluster_distance", "far VPLs as clusters: connected one by one only within this many gather cells, each farther cell's VPLs once (CPU only; default 2: the default scene's 5% image error in 0.65 s instead of 1.9 s, 34x below the path tracer on 2 cores)")
            .open_range(Range { min: Some(0.0), max: Some(16.0), min_exclusive: false, max_exclusive: false })
            .zero("every VPL one by one"),
        SettingSpec::int("gather_resolution", "largest side of the coarse gather grid").range(2.0, 256.0),
        SettingSpec::int("output_resolution", "largest side of the returned scattering grid").range(2.0, 1024.0),
        SettingSpec::bool("upsample", "joint bilateral upsampling guided by the density (off: trilinear)"),
        SettingSpec { choices: &["mean", "linear"], ..SettingSpec::new("upsample_fit", SettingType::Choice, "upsampling's estimate of J: the weighted mean (default; best on the dense cloud) or a weighted linear fit (flux right at a medium's surface: cube g 0 8 seeds x1.013 against x1.079)") },
SettingSpec::float("near_refine", "radius in gather cells within which the VPLs are gathered at each output point, not upsampled (0: off)")
            .open_range(Range { min: Some(0.0), max: Some(4.0), min_exclusive: false, max_exclusive: false }),
        SettingSpec { choices: &["plain", "ratio"], ..SettingSpec::new("near_upsample", SettingType::Choice, "near field at the output points: upsampled with the rest (default), or the gather's ball kernel corrected to the output's from the density (ratio: point light beside the plume x0.934 -> x0.950 at 32768 walks, a third of a 32-cell gather's gain; cubes 1-2% brighter)") },
        SettingSpec::float("near_radius", "near_upsample ratio: radius in gather cells of the near part that sets the light's level")
            .open_range(Range { min: Some(0.5), max: Some(4.0), min_exclusive: false, max_exclusive: false }),
        SettingSpec::float("range_sigma", "range sigma of the bilateral filter, a fraction of the largest density")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("spatial_sigma", "spatial sigma of the bilateral filter, in gather cells")
            .open_range(Range { min: Some(0.0), max: Some(4.0), min_exclusive: true, max_exclusive: false }),
        SettingSpec::int("dome_directions", "dome directions of the exact single scattering").range(1.0, 1024.0),
        SettingSpec::int("dome_spacing", "the single scattering's sky marched on every n-th output point and blended between (CPU only, grids of 64 points or more; default 2: the default scene's single scattering 0.43 -> 0.10-0.16 s, its grid within 0.012 rel. RMSE)").range(1.0, 8.0),
        SettingSpec::int("seed", "random seed (walk w is stream w: deterministic for a seed)"),
    ],
    defaults: || serde_json::to_value(vpl::VplSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"walks": 1024, "gather_resolution": 12, "output_resolution": 48}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"walks": 4096, "gather_resolution": 16, "output_resolution": 64}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"walks": 16384, "gather_resolution": 24, "output_resolution": 128}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(vpl::Vpl::from_settings(m)?))),
    gpu: true,
};

const PHOTON_GRID: SolverEntry = SolverEntry {
    name: "photon-grid",
    label: "Photon Grid",
    help: "photon beams into a grid of HG lobes (paper 04): every scattering order, for thick bright clouds. Image rel. RMSE against the reference at 2^17 photons: cube g 0 0.03, cube g 0.9 0.16, plume 0.20, dense cloud (optical depth 30+) 0.21 (0.15 at 2^20, 0.14 at 2^22: a bias floor; 5% is not reached); noise falls as photons^-0.47. At g 0.9 its HG lobe per cell is the bias (cube g 0.9 image x0.92; the cloud's shadowed foot 20-30% too dark): angular: camera weights each photon by the exact phase towards the camera instead (CPU only), cube g 0.9 x1.01, dense cloud 0.087 at 2^22 and 0.060 at 2^24 photons (23 s), no bias left above the noise. The paper's upsampling (upsampling: physical) gives the better grid on the cubes, the worse image on 5 of 6 scenes. In a session with generations m > 1 a frame costs 1/m of a solve and lags up to m-1 frames (moving sun 0.5 deg/frame: within 1.5% plus noise of a fresh solve). On a GPU the photon tracing, the reconstruction (both upsamplings) and exact single scattering run on the device (tracing: other random numbers, equal in distribution, S within the noise of two seeds on lavapipe; reconstruction: equal to the CPU's within 6.4e-7 of the largest S on lavapipe; angular: camera traces on the CPU). Benchmark scenes (BENCHMARKS.md solvers, image rel. RMSE at preview, 1.4-2.8 s on 2 cores): thin smoke and overcast 0.04, fire-lit smoke 0.05, dense cloud 0.25 (the best there; 0.22 at final), lamp inside smoke 0.42",
    settings: &[
        SettingSpec::int("photons", "photons traced per solve, equal flux each").range(1.0, (1u32 << 30) as f64),
        SettingSpec::int("seed", "random seed (deterministic for a seed, any thread count)"),
        SettingSpec::int("cache_resolution", "cells along the longest side of the photon cache").range(2.0, 256.0),
        SettingSpec::int("output_resolution", "largest side of the returned scattering grid").range(2.0, 1024.0),
        SettingSpec::int("majorant_resolution", "cells per axis of the majorant grid used for Woodcock tracking").range(1.0, 512.0),
        SettingSpec {
            name: "single_scattering",
            kind: SettingType::Choice,
            range: None,
            zero: None,
            choices: &["exact", "photons"],
            help: "single scattering from the compositor's shadow rays (exact) or from the photons",
        },
        SettingSpec::float("cutoff", "a beam stops when its weight falls below this (biased; 0: never)")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: false, max_exclusive: true }),
        SettingSpec {
            name: "similarity",
            kind: SettingType::Choice,
            range: None,
            zero: None,
            choices: &["sqrt", "linear", "off"],
            help: "reduced scattering after the similarity switch: sigma_s sqrt(1-g), sigma_s (1-g), or no switch",
        },
        SettingSpec::float("similarity_threshold", "switch once g^bounces falls below this (the paper's t)")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: true, max_exclusive: true }),
        SettingSpec {
            name: "upsampling",
            kind: SettingType::Choice,
            range: None,
            zero: None,
            choices: &["trilinear", "physical"],
            help: "cache to output grid: mass-weighted trilinear (default: the better image on 5 of 6 fixtures), or the paper's physically based upsampling (exponential/linear weights, g^delta; better grid on the cubes)",
        },
        SettingSpec {
            name: "angular",
            kind: SettingType::Choice,
            range: None,
            zero: None,
            choices: &["lobes", "camera"],
            help: "what a cache cell keeps of the light's directions: two HG lobes (default, any view, GPU) or S towards this camera, each photon weighted by the exact phase (no lobe bias, noisier; CPU only; best with similarity off). Image error, lobes against camera: dense cloud 0.14 floor against 0.12 at 2^20, 0.087 at 2^22, 0.060 at 2^24 photons; at 2^19 cube g 0.7 0.071 against 0.045, plume 0.176 against 0.137, cube g 0.9 0.129 (x0.92) against 0.145 (x1.01)",
        },
        SettingSpec::int(
            "generations",
            "temporal ring m: in a session each frame traces photons/m new photons and drops the oldest m-th (1/m the cost, up to m-1 frames of lag); 1: every frame solved afresh",
        )
        .range(1.0, 128.0),
    ],
    defaults: || serde_json::to_value(photon_grid::PhotonGridSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"photons": 65536, "cache_resolution": 16, "output_resolution": 48}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"photons": 262144, "cache_resolution": 24, "output_resolution": 64}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"photons": 2097152, "cache_resolution": 48, "output_resolution": 128}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(photon_grid::PhotonGrid::from_settings(m)?))),
    gpu: true,
};

const NETWORK: SolverEntry = SolverEntry {
    name: "network",
    label: "Illumination Networks",
    help: "illumination networks (paper 02): particles linked along D directions, view-independent multiple scattering. Image rel. RMSE at 2048 particles, 64 directions: cubes 0.09-0.12, plume 0.20; NOT for dense clouds: the optical-depth-30 cloud comes out 0.36x too dark (image error 0.69). In a session a camera move re-splats without iterating (exactly the full solve). Benchmark scenes (BENCHMARKS.md solvers, image rel. RMSE at preview, 0.5-2.5 s on 2 cores): thin smoke and overcast 0.09, fire-lit smoke 0.23, lamp inside smoke 0.46, dense cloud 0.63",
    settings: &[
        SettingSpec::int("particles", "particles N, sampled in proportion to sigma_t").range(16.0, 65536.0),
        SettingSpec::int("directions", "directions D of the network (Fibonacci lattice)").range(6.0, 1024.0),
        SettingSpec::int("window", "side M of each direction's orthographic window").range(1.0, 4096.0).zero("the paper's bound M^2 <= D (R tau)^2 / pi"),
        SettingSpec {
            choices: &["boundary", "segment"],
            ..SettingSpec::new("opacity", SettingType::Choice, "a pair's optical depth: difference of their depths to the boundary, or along the segment between them")
        },
        SettingSpec::int("max_iterations", "cap on iterations (one scattering order each)").range(1.0, 100_000.0),
        SettingSpec::float("residual_threshold", "stop when an iteration changes the network by less than this fraction")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: false, max_exclusive: true }),
        SettingSpec::int("seed", "random seed of the particle positions"),
        SettingSpec::int("output_resolution", "largest side of the returned scattering grid").range(2.0, 1024.0),
        SettingSpec::float("kernel_radius", "spatial sigma of the splatting kernel, in particle radii")
            .open_range(Range { min: Some(0.0), max: Some(8.0), min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("range_sigma", "density sigma of the splatting kernel, a fraction of the largest density")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }),
        SettingSpec::int("dome_directions", "directions the dome's direct light is sampled with").range(1.0, 1024.0),
    ],
    defaults: || serde_json::to_value(network::NetworkSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"particles": 512, "directions": 32, "output_resolution": 32}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"particles": 2048, "directions": 64, "output_resolution": 64}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"particles": 8192, "directions": 128, "output_resolution": 128}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(network::Network::from_settings(m)?))),
    gpu: true,
};

const LPM: SolverEntry = SolverEntry {
    name: "lpm",
    label: "Light Propagation Maps",
    help: "light propagation maps (paper 05): deterministic discrete ordinates, every order to a threshold, streamed in slices under a memory budget. Benchmark scenes (BENCHMARKS.md solvers, image rel. RMSE at preview, 1-4 s on 2 cores, with the delta-M split of the forward peak, delta_m, on): overcast 0.02, thin smoke 0.03, fire-lit smoke 0.05, dense cloud 0.29, lamp inside smoke 0.38; final 0.01-0.05 on the smokes in 23-37 s. On the g 0.9 test fixtures delta-M took a cube from 0.40 to 0.15 and the plumes from 0.16-0.25 to 0.08-0.17. For media larger than memory: out_of_core, and the scene's medium.max_resolution reads a VDB box-filtered as it is read (a 1024^3 cumulus solved in 45 MiB peak RSS, 5-10 s, 0.010 from the whole load; BENCHMARKS.md lpm-region); the Blender add-on offers that for volumes whose dense size exceeds 1 GiB or half the memory budget, with the memory it will use (vs_scene_lpm_estimate)",
    settings: &[
        SettingSpec::int("grid_resolution", "cells of the propagation grid along the longest side").range(2.0, 512.0),
        SettingSpec::int("directions", "propagation directions per cube face (a perfect square; the paper's 25)").range(1.0, 256.0),
        SettingSpec::int("storage_per_face", "storage directions m = 6 x this^2 (1: the paper's 6, enough for g > 0.5 with delta_m on; more costs 4-25x the collect)").range(1.0, 32.0),
        SettingSpec::float("epsilon", "stop when an order's largest U falls below this fraction of the first order's")
            .open_range(Range { min: Some(0.0), max: Some(1.0), min_exclusive: true, max_exclusive: true }),
        SettingSpec::int("max_orders", "cap on propagated orders").range(1.0, 100_000.0),
        SettingSpec {
            choices: &["exact", "boundary"],
            ..SettingSpec::new("first_order", SettingType::Choice, "first scattering of distant lights: exact transmittance to every cell, or the paper's boundary radiance in one bin")
        },
        SettingSpec::bool("delta_m", "delta-M split of the phase function's forward peak (f = g^2): the peak's light goes on unscattered, the direction bins carry the broad rest; much closer at g 0.9 (cube 0.15 against 0.40 image error), the same at g 0"),
        SettingSpec::int("memory_budget", "bytes for the propagation's slice buffers (with out_of_core: for everything a slice holds, the per-cell arrays included); the slice thickness is picked from it (0: one slice, the whole volume)"),
        SettingSpec::bool("out_of_core", "keep the per-cell arrays in scratch files (TMPDIR) a slab at a time, so that memory_budget bounds the whole solve: grids larger than memory; CPU, first_order boundary, no local lights"),
        SettingSpec::int("output_resolution", "largest side of the returned scattering grid").range(2.0, 1024.0),
        SettingSpec::bool("upsample", "joint bilateral upsampling guided by the density (off: trilinear)"),
        SettingSpec::float("range_sigma", "range sigma of the bilateral filter, a fraction of the largest density")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("spatial_sigma", "spatial sigma of the bilateral filter, in propagation cells")
            .open_range(Range { min: Some(0.0), max: Some(4.0), min_exclusive: true, max_exclusive: false }),
        SettingSpec::int("dome_directions", "dome directions of the exact single scattering").range(1.0, 1024.0),
    ],
    defaults: || serde_json::to_value(lpm::LpmSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: DRAFT, settings_json: r#"{"grid_resolution": 16, "directions": 9, "output_resolution": 48}"# },
        Preset { name: "preview", help: PREVIEW, settings_json: r#"{"grid_resolution": 32, "directions": 25, "output_resolution": 64}"# },
        Preset { name: "final", help: FINAL, settings_json: r#"{"grid_resolution": 64, "directions": 49, "output_resolution": 128}"# },
    ],
    make: Make::Solver(|m| Ok(Box::new(lpm::Lpm::from_settings(m)?))),
    gpu: true,
};

const AUTO: SolverEntry = SolverEntry {
    name: auto::NAME,
    label: "Automatic",
    help: AUTO_HELP,
    settings: &[
        SettingSpec::float("target_error", "image relative RMSE to reach: the cheapest measured solver and quality predicted to reach it runs")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: true, max_exclusive: false }),
        SettingSpec::float("time_budget", "seconds the solve may take (CPU, solve + composite); with a budget the lowest predicted error within it runs (0: no budget)")
            .open_range(Range { min: Some(0.0), max: None, min_exclusive: false, max_exclusive: false }),
    ],
    defaults: || serde_json::to_value(auto::AutoSettings::default()).unwrap_or(Value::Null),
    lights: &LightType::ALL,
    presets: &[
        Preset { name: "draft", help: "target image error 0.3", settings_json: r#"{"target_error": 0.3}"# },
        Preset { name: "preview", help: "target image error 0.25 (the default)", settings_json: r#"{"target_error": 0.25}"# },
        Preset { name: "final", help: "target image error 0.1", settings_json: r#"{"target_error": 0.1}"# },
    ],
    make: Make::Picker(auto::validate),
    // Resolved to the chosen solver before the device dispatch (volscatter-gpu solve.rs), so
    // the chosen solver's GPU backend runs where it has one.
    gpu: false,
};

/// `auto`'s help, with the numbers of the committed measurements.
const AUTO_HELP: &str = "picks the solver and its quality for the scene (optical depth, albedo, g, light types, size) and a target image error (default 0.25) or a time budget, from a model fitted to measurements (core/src/pipeline/auto/measurements.json, written by scripts/bench_solvers.py: 5 Blender scenes, 69 runs), and says what it picked and why (--report `auto`, vs_result_choice). On every measured scene it reaches each measured error within 1.25x at under 2x the cheapest measured cost; for a scene left out of the fit, 38 of 69 picks were within 2x the target (five scenes are few). A light type no measured scene has (a local light outside the medium) runs pop preview";

/// Every solver, in menu order. The hosts default to `auto` (by name: it comes last so that the
/// others keep the positions hosts and files already store).
pub const SOLVERS: &[SolverEntry] = &[REFERENCE, POP, VPL, PHOTON_GRID, NETWORK, LPM, AUTO];

/// The solvers' names, in `SOLVERS` order.
pub const SOLVER_NAMES: &[&str] = &names::<{ SOLVERS.len() }>();

const fn names<const N: usize>() -> [&'static str; N] {
    let mut out = [""; N];
    let mut i = 0;
    while i < N {
        out[i] = SOLVERS[i].name;
        i += 1;
    }
    out
}

/// Builds solver `name` with `settings` (unknown names refused with the list of known ones).
pub fn build(name: &str, settings: &Map<String, Value>) -> Result<Box<dyn Solver>> {
    get(name)?.build(settings)
}

/// The settings of solver `name`'s preset `quality` (empty when either is unknown).
pub fn preset_settings(name: &str, quality: &str) -> Map<String, Value> {
    get(name).ok().and_then(|e| e.preset(quality)).map(|p| p.settings()).unwrap_or_default()
}

/// The entry of solver `name`, or an error listing the known ones.
pub fn get(name: &str) -> Result<&'static SolverEntry> {
    SOLVERS
        .iter()
        .find(|s| s.name == name)
        .ok_or_else(|| Error::InvalidArgument(format!("unknown solver `{name}` (known: {})", SOLVER_NAMES.join(", "))))
}

/// The registry as JSON: `{"format": 1, "solvers": [...], "light_types": [...]}` (the form of
/// `volscatter solvers` and `vs_solvers_json`, documented in docs/solvers.md).
pub fn to_json() -> Value {
    let lights: Vec<Value> = LightType::ALL.iter().map(|l| serde_json::json!({"name": l.name(), "help": l.help()})).collect();
    serde_json::json!({
        "format": 1,
        "solvers": SOLVERS.iter().map(SolverEntry::to_json).collect::<Vec<_>>(),
        "light_types": lights,
    })
}

#[cfg(test)]
#[path = "registry_tests.rs"]
mod tests;
