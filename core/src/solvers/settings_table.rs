//! A solver's settings, declared once: the `settings!` macro turns one table (per field: name,
//! Rust type, default, range, what 0 stands for, one sentence of help, and a doc comment saying
//! why) into the settings struct (serde, `deny_unknown_fields`, `Default`), the range checks
//! of its `validate()` and the `&'static [SettingSpec]` the registry lists. `setting_choices!`
//! declares an enum setting with the strings the scene JSON names its variants by.
//!
//! Each solver's `settings.rs` also holds its registry entry (`ENTRY`: label, help, lights,
//! presets, constructor), so that adding a setting or a solver touches one folder; the
//! registry (registry.rs) is the list of those entries.
//!
//! ```ignore
//! settings! {
//!     /// Settings of `pop`.
//!     pub struct PopSettings {
//!         /// Why this default (a sentence or two; measurements go to docs/solvers/pop.md).
//!         grid_resolution: u32 = 32, range(>= 2, <= 512),
//!             "cells along the longest side of each light's propagation grid";
//!         merge_resolution: u32 = 0, range(>= 2, <= 1024), zero("twice grid_resolution"),
//!             "largest side of the medium-aligned grid the lights are merged into";
//!         residual_threshold: f32 = 1e-3, range(>= 0, < 1),
//!             "stop when the travelling energy falls below this fraction of the scattered";
//!         upsample: bool = true, "joint bilateral upsampling guided by the density (off: trilinear)";
//!     }
//!     check = cross_checks;   // optional: fn(&Self) -> Result<()> for checks across fields
//! }
//! ```

use serde::Serialize;
use serde_json::{Map, Value};

use super::Solver;
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

impl std::fmt::Display for Range {
    /// Interval notation: `[2, 512]`, `(0, 1)`, `>= 0`, `> 0`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.min, self.max) {
            (Some(lo), Some(hi)) => {
                let (l, r) = (if self.min_exclusive { '(' } else { '[' }, if self.max_exclusive { ')' } else { ']' });
                write!(f, "{l}{lo}, {hi}{r}")
            }
            (Some(lo), None) => write!(f, "{} {lo}", if self.min_exclusive { ">" } else { ">=" }),
            (None, Some(hi)) => write!(f, "{} {hi}", if self.max_exclusive { "<" } else { "<=" }),
            (None, None) => write!(f, "any value"),
        }
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
    /// One sentence (a host's tooltip).
    pub help: &'static str,
}

impl SettingSpec {
    /// The range check of `validate()` for this setting's value `v` (None for bools and
    /// choices, which serde checks): a float must be finite; a value must lie in `range`, or
    /// be 0 where `zero` says what 0 stands for.
    pub fn check(&self, v: Option<f64>) -> Result<()> {
        let Some(v) = v else { return Ok(()) };
        let refuse = |what: String| Err(Error::scene(format!("solver.{}", self.name), format!("must be {what}, got {v}")));
        if !v.is_finite() {
            return refuse("finite".into());
        }
        match (self.range, self.zero) {
            (_, Some(_)) if v == 0.0 => Ok(()),
            (Some(r), zero) if !r.contains(v) => {
                let range = if r.min.is_some() && r.max.is_some() { format!("in {r}") } else { r.to_string() };
                match zero {
                    Some(means) => refuse(format!("0 ({means}) or {range}")),
                    None => refuse(range),
                }
            }
            _ => Ok(()),
        }
    }
}

/// What a settings struct's field type says about its setting: its JSON type, its choices (for
/// an enum declared with `setting_choices!`) and its value as a number for the range check.
pub trait SettingValue {
    const KIND: SettingType;
    const CHOICES: &'static [&'static str] = &[];
    /// The value for the range check (None: not a number).
    fn number(&self) -> Option<f64> {
        None
    }
}

macro_rules! number_setting {
    ($kind:ident: $($t:ty),*) => {$(
        impl SettingValue for $t {
            const KIND: SettingType = SettingType::$kind;
            fn number(&self) -> Option<f64> {
                Some(*self as f64)
            }
        }
    )*};
}
number_setting!(Int: u32, u64);
number_setting!(Float: f32, f64);

impl SettingValue for bool {
    const KIND: SettingType = SettingType::Bool;
}

/// Named settings a host offers as one choice (the Blender add-on's Quality menu), or the
/// registry's `test` preset. Values not named keep the solver's defaults.
#[derive(Clone, Copy, Debug)]
pub struct Preset {
    pub name: &'static str,
    pub help: &'static str,
    /// A JSON object of settings (checked against the constructor by a test).
    pub settings_json: &'static str,
}

/// The hosts' quality presets (the Blender add-on's Draft / Preview / Final) and the tests'.
pub const DRAFT_HELP: &str = "coarse grids, few iterations or samples";
pub const PREVIEW_HELP: &str = "the interactive default";
pub const FINAL_HELP: &str = "fine grids, many iterations or samples";
pub const TEST_HELP: &str = "small and fast, for tests: seconds on the test fixtures, not their accuracy";

impl Preset {
    pub const fn draft(settings_json: &'static str) -> Preset {
        Preset { name: "draft", help: DRAFT_HELP, settings_json }
    }
    pub const fn preview(settings_json: &'static str) -> Preset {
        Preset { name: "preview", help: PREVIEW_HELP, settings_json }
    }
    pub const fn final_(settings_json: &'static str) -> Preset {
        Preset { name: "final", help: FINAL_HELP, settings_json }
    }
    pub const fn test(settings_json: &'static str) -> Preset {
        Preset { name: "test", help: TEST_HELP, settings_json }
    }

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

/// One solver, as its `settings.rs` declares it (`ENTRY`) and the registry lists it.
#[derive(Clone, Copy)]
pub struct SolverEntry {
    pub name: &'static str,
    /// The name in hosts' menus.
    pub label: &'static str,
    /// One sentence (a host's tooltip); the measurements are in docs/solvers/<name>.md.
    pub help: &'static str,
    pub settings: &'static [SettingSpec],
    /// The settings struct's `Default`, serialised (the defaults the registry reports).
    pub defaults: fn() -> Value,
    pub lights: &'static [LightType],
    /// The hosts' quality menu: the same names for every solver.
    pub presets: &'static [Preset],
    /// Small, fast settings for tests (`preset("test")`); not in the hosts' menu or the JSON.
    pub test: Preset,
    /// The solver (or the picker) this name builds.
    pub make: Make,
    /// Whether volscatter-gpu has a backend for it (its dispatch table is tested against this).
    pub gpu: bool,
}

/// What a registry name stands for.
#[derive(Clone, Copy)]
pub enum Make {
    /// A solver, built from its settings (validated; unknown keys refused).
    Solver(CpuConstructor),
    /// A pick among the solvers for each scene (`auto`, resolved by the pipeline); the function
    /// checks its settings.
    Picker(fn(&Map<String, Value>) -> Result<()>),
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

    /// A quality preset of the hosts' menu, or `test`.
    pub fn preset(&self, name: &str) -> Option<&Preset> {
        self.presets.iter().chain(std::iter::once(&self.test)).find(|p| p.name == name)
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

/// The `defaults` of a `SolverEntry`: the settings struct's `Default`, serialised.
pub fn defaults_of<T: Default + Serialize>() -> Value {
    serde_json::to_value(T::default()).unwrap_or(Value::Null)
}

/// A setting's range from `range(...)` in `settings!`: `>= a, <= b` (closed), `>= a, < b`,
/// `> a, <= b`, `> a, < b`, or one end only (`>= a`, `> a`).
#[macro_export]
#[doc(hidden)]
macro_rules! __setting_range {
    () => { None };
    (>= $min:expr, <= $max:expr) => { $crate::__setting_range!(@ $min, false, Some(($max) as f64), false) };
    (>= $min:expr, < $max:expr) => { $crate::__setting_range!(@ $min, false, Some(($max) as f64), true) };
    (> $min:expr, <= $max:expr) => { $crate::__setting_range!(@ $min, true, Some(($max) as f64), false) };
    (> $min:expr, < $max:expr) => { $crate::__setting_range!(@ $min, true, Some(($max) as f64), true) };
    (>= $min:expr) => { $crate::__setting_range!(@ $min, false, None, false) };
    (> $min:expr) => { $crate::__setting_range!(@ $min, true, None, false) };
    (@ $min:expr, $min_ex:expr, $max:expr, $max_ex:expr) => {
        Some($crate::solvers::settings_table::Range { min: Some(($min) as f64), max: $max, min_exclusive: $min_ex, max_exclusive: $max_ex })
    };
}

/// Declares a solver's settings once (see the module doc for the syntax): the struct with
/// serde (`default`, `deny_unknown_fields`) and `Default`; `SETTINGS`, the registry's table of
/// them in declaration order; `validate()`, every declared range (and the optional `check`
/// function's cross-field checks).
#[macro_export]
macro_rules! settings {
    (
        $(#[$attr:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[$fattr:meta])*
                $field:ident : $ty:ty = $default:expr,
                    $(range($($range:tt)*),)?
                    $(zero($zero:literal),)?
                    $help:literal;
            )*
        }
        $(check = $check:path;)?
    ) => {
        $(#[$attr])*
        #[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
        #[serde(default, deny_unknown_fields)]
        $vis struct $name {
            $(
                #[doc = $help]
                #[doc = ""]
                $(#[$fattr])*
                pub $field: $ty,
            )*
        }

        impl Default for $name {
            fn default() -> Self {
                $name { $($field: $default,)* }
            }
        }

        impl $name {
            /// Every setting, in declaration order (the registry's table).
            pub const SETTINGS: &'static [$crate::solvers::settings_table::SettingSpec] = &[$(
                $crate::solvers::settings_table::SettingSpec {
                    name: stringify!($field),
                    kind: <$ty as $crate::solvers::settings_table::SettingValue>::KIND,
                    range: $crate::__setting_range!($($($range)*)?),
                    zero: $crate::__setting_zero!($($zero)?),
                    choices: <$ty as $crate::solvers::settings_table::SettingValue>::CHOICES,
                    help: $help,
                },
            )*];

            /// Refuses a value outside its declared range (naming the setting), then the
            /// checks across settings.
            pub fn validate(&self) -> $crate::error::Result<()> {
                let values: &[Option<f64>] = &[$($crate::solvers::settings_table::SettingValue::number(&self.$field)),*];
                for (spec, v) in Self::SETTINGS.iter().zip(values) {
                    spec.check(*v)?;
                }
                $($check(self)?;)?
                Ok(())
            }
        }
    };
}

#[macro_export]
#[doc(hidden)]
macro_rules! __setting_zero {
    () => {
        None
    };
    ($zero:literal) => {
        Some($zero)
    };
}

/// An enum setting: each variant with the string the scene JSON names it by, e.g.
///
/// ```ignore
/// setting_choices! {
///     /// Where the first scattering order comes from.
///     pub enum SingleScattering { Exact = "exact", Photons = "photons" }
/// }
/// ```
#[macro_export]
macro_rules! setting_choices {
    (
        $(#[$attr:meta])*
        $vis:vis enum $name:ident {
            $( $(#[$vattr:meta])* $variant:ident = $text:literal ),* $(,)?
        }
    ) => {
        $(#[$attr])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
        $vis enum $name {
            $( $(#[$vattr])* #[serde(rename = $text)] $variant, )*
        }

        impl $crate::solvers::settings_table::SettingValue for $name {
            const KIND: $crate::solvers::settings_table::SettingType = $crate::solvers::settings_table::SettingType::Choice;
            const CHOICES: &'static [&'static str] = &[$($text),*];
        }
    };
}
