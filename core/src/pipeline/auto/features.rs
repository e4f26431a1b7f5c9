//! What the `auto` solver knows about a scene before solving it: the few numbers that decide
//! which solver does well there (issue 21). Optical depth decides how many scattering orders
//! matter (thin smoke: few; a cumulus: hundreds, where `network` and `vpl` go dark); albedo
//! how much light survives them; g how forward the lobe is; the light types which solver
//! stages run (radial grids for local lights, dome ordinates, emission VPLs); the voxel and
//! pixel counts what the solve and the composite cost.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::medium::optics::optical_depth;
use crate::scene::{Light, Scene};

/// Rays per axis side of the optical-depth probe: 7 x 7 parallel rays along each of the 3
/// world axes through the medium's box (147 rays of at most 256 steps: well under a
/// millisecond on the fixtures, a few ms on a 256^3 VDB).
const PROBE_SIDE: usize = 7;
const PROBE_STEPS: u32 = 256;

/// A scene's features. Stored per measured scene in `scene_features.json`, so that the model
/// compares a new scene with the measured ones without loading them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Features {
    /// Optical depth (mean of R, G, B) through the medium's box along the world axes: the mean
    /// over the probe rays that meet any medium, and the largest.
    pub tau_mean: f64,
    pub tau_max: f64,
    /// Single-scattering albedo, the mean of R, G, B.
    pub albedo: f64,
    /// Henyey-Greenstein g.
    pub g: f64,
    /// Light types present: a distant light, a dome, a point/spot/area light inside the
    /// medium's box, one outside it, an emissive medium.
    pub lights: LightClasses,
    /// Point and spot lights inside the medium's box, at most 16: the composite computes each
    /// one's single scattering exactly near it (compositor/near_lamps.rs), at a cost per lamp.
    #[serde(default)]
    pub lamps: f64,
    /// Voxels of the medium's index box, and pixels of the camera's image.
    pub voxels: f64,
    pub pixels: f64,
}

/// Which kinds of light a scene has, split as the solvers' costs and errors split: local lights
/// inside the medium light it from within (radial grids centred in it, VPLs near the gather
/// points), outside ones like a nearby sun.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightClasses {
    pub distant: bool,
    pub dome: bool,
    pub local_inside: bool,
    pub local_outside: bool,
    pub emission: bool,
    /// The kinds of local light, wherever they sit, for the time model: a solver's cost is per
    /// kind (a point or spot light is one position to sample; an area light's surface is
    /// sampled over, lpm draft took 5x longer under a rect light than beside a point light).
    pub point: bool,
    pub area: bool,
}

impl LightClasses {
    /// (name, present) in a fixed order, for distances and sentences.
    pub fn named(&self) -> [(&'static str, bool); 5] {
        [
            ("distant", self.distant),
            ("dome", self.dome),
            ("local light inside", self.local_inside),
            ("local light outside", self.local_outside),
            ("emission", self.emission),
        ]
    }

    /// (name, present) of what sets a solver's cost, for `model::time_distance`: the light
    /// kinds (distant, dome, point or spot, area, emission), where local lights sit aside.
    pub fn kinds(&self) -> [(&'static str, bool); 5] {
        [("distant", self.distant), ("dome", self.dome), ("point", self.point), ("area", self.area), ("emission", self.emission)]
    }

    /// The names of the classes present, joined by "+" ("none" without lights).
    pub fn describe(&self) -> String {
        let present: Vec<&str> = self.named().iter().filter(|(_, p)| *p).map(|(n, _)| *n).collect();
        if present.is_empty() {
            "none".into()
        } else {
            present.join("+")
        }
    }
}

impl Features {
    pub fn of(scene: &Scene) -> Features {
        let m = &scene.medium;
        let (lo, hi) = m.world_bounds();
        let (mut sum, mut hits, mut max) = (0.0f64, 0usize, 0.0f64);
        let min_step = m.voxel_size_world().min_element().max(1e-6) * 0.5;
        if !m.grid.is_empty() && (hi - lo).min_element() > 0.0 {
            for axis in 0..3 {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let mut d = Vec3::ZERO;
                d[axis] = 1.0;
                for a in 0..PROBE_SIDE {
                    for b in 0..PROBE_SIDE {
                        let mut o = lo;
                        o[axis] = lo[axis] - 1.0;
                        o[u] = lo[u] + (hi[u] - lo[u]) * (a as f32 + 0.5) / PROBE_SIDE as f32;
                        o[v] = lo[v] + (hi[v] - lo[v]) * (b as f32 + 0.5) / PROBE_SIDE as f32;
                        let tau = optical_depth(m, o, d, f32::INFINITY, min_step, PROBE_STEPS);
                        let tau = ((tau.x + tau.y + tau.z) / 3.0) as f64;
                        if tau > 0.0 && tau.is_finite() {
                            sum += tau;
                            hits += 1;
                            max = max.max(tau);
                        }
                    }
                }
            }
        }
        let inside = |p: Vec3| p.cmpge(lo).all() && p.cmple(hi).all();
        let mut lights = LightClasses { emission: m.emission.is_some(), ..Default::default() };
        let mut lamps = 0usize;
        for l in &scene.lights {
            let local = match l {
                Light::Distant { .. } => {
                    lights.distant = true;
                    None
                }
                Light::Dome(_) => {
                    lights.dome = true;
                    None
                }
                Light::Point { position, .. } => {
                    lights.point = true;
                    Some(*position)
                }
                Light::Spot(s) => {
                    lights.point = true;
                    Some(s.position)
                }
                Light::Area(a) => {
                    lights.area = true;
                    Some(a.center)
                }
            };
            if let Some(p) = local {
                if inside(p) {
                    lights.local_inside = true;
                    lamps += usize::from(matches!(l, Light::Point { .. } | Light::Spot(_)));
                } else {
                    lights.local_outside = true;
                }
            }
        }
        let (ilo, ihi) = m.index_bounds();
        let extent = (ihi - ilo).max(Vec3::ONE);
        Features {
            tau_mean: if hits > 0 { sum / hits as f64 } else { 0.0 },
            tau_max: max,
            albedo: ((m.albedo.x + m.albedo.y + m.albedo.z) / 3.0) as f64,
            g: m.g as f64,
            lights,
            lamps: lamps.min(crate::compositor::NEAR_LAMPS_MAX) as f64,
            voxels: extent.x as f64 * extent.y as f64 * extent.z as f64,
            pixels: scene.camera.width as f64 * scene.camera.height as f64,
        }
    }

    /// The scattering orders an iterative solve runs on this medium before an order's light falls
    /// below `epsilon` (at most `max_orders`): lpm's cost model (solvers/lpm/cost.rs
    /// `predicted_orders`, diffusion's slowest mode), here from the probe's mean optical depth
    /// under the similarity (1 - albedo g). Thick white media keep scattering for hundreds of
    /// orders, which no light class or size tells (issue 40: the dense white furnace).
    pub fn scattering_orders(&self, epsilon: f64, max_orders: f64) -> f64 {
        let a = self.albedo.clamp(0.0, 1.0);
        let tau = self.tau_mean.max(0.0) * (1.0 - a * self.g.clamp(-1.0, 1.0)).max(0.0);
        let lambda = a / (1.0 + (std::f64::consts::PI / (tau + 1.42)).powi(2) / 3.0);
        let orders = if lambda <= 0.0 || !(epsilon > 0.0 && epsilon < 1.0) { 1.0 } else { (epsilon.ln() / lambda.ln()).ceil() + 1.0 };
        orders.clamp(1.0, max_orders.max(1.0))
    }

    /// One line for the `why` sentence.
    pub fn describe(&self) -> String {
        format!(
            "optical depth {:.1} (max {:.1}), albedo {:.3}, g {:.2}, lights {}",
            self.tau_mean,
            self.tau_max,
            self.albedo,
            self.g,
            self.lights.describe()
        )
    }
}
