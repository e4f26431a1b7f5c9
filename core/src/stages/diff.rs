//! What changed in a scene since a session's previous frame: the medium, each light, the
//! camera. Exact keys (every value's bits), so that a stage kept because its inputs' keys are
//! equal gives the bits a one-off solve would.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};

use crate::medium::key::{grid_fingerprint, MediumKey};
use crate::medium::Medium;
use crate::scene::{Camera, Light, Scene};

/// A hasher fed with the exact bits of values (f32 through `to_bits`): the keys of what a
/// session and the GPU context keep.
pub struct Bits(DefaultHasher);

impl Default for Bits {
    fn default() -> Self {
        Self::new()
    }
}

impl Bits {
    pub fn new() -> Self {
        Bits(DefaultHasher::new())
    }
    pub fn f32s(&mut self, v: impl IntoIterator<Item = f32>) -> &mut Self {
        v.into_iter().for_each(|x| x.to_bits().hash(&mut self.0));
        self
    }
    pub fn u64(&mut self, v: u64) -> &mut Self {
        v.hash(&mut self.0);
        self
    }
    /// Raw bytes, with their count.
    pub fn bytes(&mut self, v: &[u8]) -> &mut Self {
        v.hash(&mut self.0);
        self
    }
    /// A value by its `Debug` text: Rust prints floats so that they read back to the same bits.
    pub fn debug(&mut self, v: &impl std::fmt::Debug) -> &mut Self {
        format!("{v:?}").hash(&mut self.0);
        self
    }
    pub fn finish(&self) -> u64 {
        self.0.finish()
    }
}

/// A light's exact key: its every parameter, a dome map by its pixels' bits (not its text,
/// which for a 2k map is megabytes).
pub fn light_key(light: &Light) -> u64 {
    let mut h = Bits::new();
    match light {
        Light::Dome(env) => {
            h.u64(1).f32s(env.color.to_array());
            if let Some(m) = &env.map {
                h.u64(m.width as u64).u64(m.height as u64).f32s(m.pixels.iter().flat_map(|p| p.to_array()));
            }
        }
        other => {
            h.u64(0).debug(other);
        }
    }
    h.finish()
}

/// The medium's exact key with its emission (MediumKey leaves emission out: the
/// light-independent stages it serves do not read it).
pub fn medium_key(medium: &Medium) -> (MediumKey, u64) {
    let mut h = Bits::new();
    if let Some(e) = &medium.emission {
        h.u64(e.vpl_count as u64);
        for t in &e.terms {
            h.u64(grid_fingerprint(&t.grid)).debug(&t.index_to_world).debug(&t.law);
        }
    }
    (MediumKey::of(medium), h.finish())
}

pub fn camera_key(camera: &Camera) -> u64 {
    Bits::new().debug(camera).finish()
}

/// The keys of one frame's scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneKeys {
    medium: (MediumKey, u64),
    lights: Vec<u64>,
    camera: u64,
}

impl SceneKeys {
    pub fn of(scene: &Scene) -> Self {
        SceneKeys { medium: medium_key(&scene.medium), lights: scene.lights.iter().map(light_key).collect(), camera: camera_key(&scene.camera) }
    }
}

/// What changed since the previous frame of a session (everything, on its first frame).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SceneDiff {
    /// The first frame, or the solver was rebuilt (`auto` picked another): nothing to compare.
    pub first: bool,
    pub medium: bool,
    /// Per light of this frame: whether it is new or changed (a light equal to one of the
    /// previous frame's, wherever it was in the list, is unchanged).
    pub lights: Vec<bool>,
    /// Lights of the previous frame that are gone.
    pub lights_removed: usize,
    pub camera: bool,
}

impl SceneDiff {
    /// The diff of a first frame: everything is new.
    pub fn first(scene_lights: usize) -> Self {
        SceneDiff { first: true, medium: true, lights: vec![true; scene_lights], lights_removed: 0, camera: true }
    }

    pub fn between(before: &SceneKeys, now: &SceneKeys) -> Self {
        let lights: Vec<bool> = now.lights.iter().map(|k| !before.lights.contains(k)).collect();
        let kept = now.lights.iter().filter(|k| before.lights.contains(k)).count();
        SceneDiff {
            first: false,
            medium: before.medium != now.medium,
            lights,
            lights_removed: before.lights.len().saturating_sub(kept),
            camera: before.camera != now.camera,
        }
    }

    pub fn lights_changed(&self) -> bool {
        self.first || self.lights.iter().any(|&c| c) || self.lights_removed > 0
    }

    /// Nothing but (at most) the camera changed.
    pub fn camera_only(&self) -> bool {
        !self.first && !self.medium && !self.lights_changed()
    }

    /// Nothing changed at all.
    pub fn nothing(&self) -> bool {
        self.camera_only() && !self.camera
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    fn scene() -> Scene {
        let mut sc = Scene::from_json_str(&crate::scene::DEFAULT_SCENE_JSON.replace(r#""dims": [64]"#, r#""dims": [12]"#), std::path::Path::new(".")).unwrap();
        sc.camera.width = 8;
        sc.camera.height = 8;
        sc
    }

    /// Each kind of change is told apart, and a change of one light names that light only.
    #[test]
    fn scene_diff_names_what_changed() {
        let a = scene();
        let keys = SceneKeys::of(&a);
        assert!(SceneDiff::between(&keys, &SceneKeys::of(&a)).nothing(), "the same scene");
        let mut moved = a.clone();
        moved.camera.position.x += 1e-3;
        let d = SceneDiff::between(&keys, &SceneKeys::of(&moved));
        assert!(d.camera_only() && d.camera && !d.nothing());
        let mut turned = a.clone();
        let k = turned.lights.iter().position(|l| matches!(l, Light::Distant { .. })).expect("the default scene has a sun");
        if let Light::Distant { direction, .. } = &mut turned.lights[k] {
            *direction = Quat::from_rotation_z(0.1) * *direction;
        }
        let d = SceneDiff::between(&keys, &SceneKeys::of(&turned));
        assert!(!d.camera && !d.medium && d.lights_changed());
        assert_eq!(d.lights.iter().filter(|&&c| c).count(), 1, "one light changed: {d:?}");
        assert!(d.lights[k]);
        let mut denser = a.clone();
        denser.medium.density_scale *= 1.0 + f32::EPSILON;
        let d = SceneDiff::between(&keys, &SceneKeys::of(&denser));
        assert!(d.medium && !d.camera && !d.lights_changed());
        let mut fewer = a.clone();
        fewer.lights.pop();
        let d = SceneDiff::between(&keys, &SceneKeys::of(&fewer));
        assert_eq!((d.lights_removed, d.lights.iter().any(|&c| c)), (1, false));
        assert!(!SceneDiff::first(1).camera_only());
        let _ = Vec3::ZERO;
    }
}
