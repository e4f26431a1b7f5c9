//! What POP keeps between the frames of a session (pipeline/session.rs): the stages that depend
//! on the medium (and the camera) but not on the lights, so that a moving sun or a moving light
//! recomputes only its own grids.
//! - the density mip (mip.rs), keyed on the density grid's voxels and the finest footprint
//!   asked of it (which follows from the medium's transform and the settings);
//! - the dome's directional importance map (importance.rs), keyed on the whole medium (voxels,
//!   transform, material), the camera position and `diffusion_correction`;
//! - each distant ordinate's propagated light (its grid, J, energy report and the packets it
//!   hands to the residuum), keyed on the ordinate (direction, fluence, initial anisotropy,
//!   grid resolution) for the medium, camera position and settings they were solved with: while
//!   the sun moves, the dome's ordinates stay. Only backends that can copy their lights out
//!   (the CPU's; `PopBackend::keep_light`) keep them.
//!
//! Keys are exact (bit patterns and a hash of every stored voxel), so a reused value is the
//! one a recompute would give: a session is bit-identical to one-off solves. The hash costs one
//! pass over the stored voxels, about what the mip costs to build, and far less than the
//! importance propagation (BENCHMARKS.md "Sessions").

use std::sync::Arc;

use glam::Vec3;

use std::any::Any;

use super::backend::PopBackend;
use super::dome::DirectionalMap;
use super::light_grid::LightGrid;
use crate::stages::mip::MediumMip;
use super::residuum::Residuum;
use super::settings::PopSettings;
use super::LightReport;
use crate::medium::key::MediumKey;
use crate::medium::Medium;

/// How often each kept stage was reused and recomputed over a session.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReuseCounts {
    pub mip_reused: u32,
    pub mip_built: u32,
    pub importance_reused: u32,
    pub importance_built: u32,
    pub lights_reused: u32,
    pub lights_solved: u32,
}

/// A distant ordinate as `Pop`'s solve builds its grid: direction of travel, fluence,
/// initial anisotropy (bits) and grid resolution.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OrdinateKey([u32; 8]);

impl OrdinateKey {
    pub fn new(direction: Vec3, fluence: Vec3, a0: f32, resolution: u32) -> Self {
        let d = direction.to_array().map(f32::to_bits);
        let f = fluence.to_array().map(f32::to_bits);
        OrdinateKey([d[0], d[1], d[2], f[0], f[1], f[2], a0.to_bits(), resolution])
    }
}

/// One ordinate's solved light, as it went into the residuum and the merge.
struct KeptLight {
    grid: LightGrid,
    light: Box<dyn Any + Send>,
    report: LightReport,
    /// The packets handed to the residuum (empty without it).
    remaining: Vec<Vec3>,
}

/// What the kept lights were solved for: the medium, the camera position (the view cosines of
/// the accumulation) and the settings.
type LightsFor = (MediumKey, [u32; 3], PopSettings);

#[derive(Default)]
pub struct PopReuse {
    mip: Option<(u64, u32, Arc<MediumMip>)>,
    importance: Option<(MediumKey, [u32; 3], bool, Arc<DirectionalMap>)>,
    lights_for: Option<LightsFor>,
    /// The previous frame's lights, and this frame's so far.
    lights: Vec<(OrdinateKey, KeptLight)>,
    next: Vec<(OrdinateKey, KeptLight)>,
    pub counts: ReuseCounts,
}

impl PopReuse {
    /// The mip of `medium`'s density for footprints from `min_footprint` voxels: the kept one
    /// when it was built from the same voxels and footprint, else a new one (then kept).
    pub fn mip(&mut self, key: &MediumKey, medium: &Medium, min_footprint: f32) -> Arc<MediumMip> {
        let fp = min_footprint.to_bits();
        match &self.mip {
            Some((g, f, mip)) if *g == key.grid && *f == fp => {
                self.counts.mip_reused += 1;
                mip.clone()
            }
            _ => {
                let mip = Arc::new(MediumMip::new(medium, min_footprint));
                self.mip = Some((key.grid, fp, mip.clone()));
                self.counts.mip_built += 1;
                mip
            }
        }
    }

    /// The kept importance map for this medium, camera position and setting, or the one
    /// `build` makes (then kept). A failed build keeps nothing.
    pub fn importance<E>(
        &mut self,
        key: &MediumKey,
        camera: Vec3,
        diffusion_correction: bool,
        build: impl FnOnce() -> Result<DirectionalMap, E>,
    ) -> Result<Arc<DirectionalMap>, E> {
        let cam = camera.to_array().map(f32::to_bits);
        if let Some((k, c, d, map)) = &self.importance {
            if k == key && *c == cam && *d == diffusion_correction {
                self.counts.importance_reused += 1;
                return Ok(map.clone());
            }
        }
        let map = Arc::new(build()?);
        self.importance = Some((key.clone(), cam, diffusion_correction, map.clone()));
        self.counts.importance_built += 1;
        Ok(map)
    }

    /// Starts a frame's distant lights: the kept ones stay reusable only when solved for this
    /// medium, camera position and settings.
    pub fn begin_lights(&mut self, key: &MediumKey, camera: Vec3, settings: &PopSettings) {
        let now = (key.clone(), camera.to_array().map(f32::to_bits), settings.clone());
        if self.lights_for.as_ref() != Some(&now) {
            self.lights.clear();
            self.next.clear();
            self.lights_for = Some(now);
        }
        // A frame that failed part-way left its lights in `next`: still valid.
        let unfinished = std::mem::take(&mut self.next);
        self.lights.extend(unfinished);
    }

    /// The kept light of ordinate `key` as `backend`'s light, with its grid and report, its
    /// residuum packets gathered into `residuum` as a fresh solve would; kept for the next
    /// frame again. `None` when there is none (or the backend cannot take it back).
    pub fn reuse_light<B: PopBackend>(
        &mut self,
        key: &OrdinateKey,
        backend: &B,
        residuum: Option<&mut Residuum>,
    ) -> Option<(LightGrid, B::Light, LightReport)> {
        let i = self.lights.iter().position(|(k, _)| k == key)?;
        let light = backend.reuse_light(&*self.lights[i].1.light)?;
        let (key, kept) = self.lights.swap_remove(i);
        if let Some(r) = residuum {
            r.gather(&kept.grid, &kept.remaining);
        }
        let out = (kept.grid.clone(), light, kept.report.clone());
        self.next.push((key, kept));
        self.counts.lights_reused += 1;
        Some(out)
    }

    /// Keeps a freshly solved light for the next frame (when the backend can copy it).
    pub fn keep_light<B: PopBackend>(&mut self, key: OrdinateKey, backend: &B, grid: &LightGrid, light: &B::Light, report: &LightReport, remaining: Vec<Vec3>) {
        self.counts.lights_solved += 1;
        if let Some(light) = backend.keep_light(light) {
            self.next.push((key, KeptLight { grid: grid.clone(), light, report: report.clone(), remaining }));
        }
    }

    /// Ends a frame's distant lights: the ones it used are the ones kept.
    pub fn end_lights(&mut self) {
        self.lights = std::mem::take(&mut self.next);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::DensityGrid;
    use crate::solvers::SolveCtx;
    use crate::scene::Scene;
    use crate::solvers::session::SessionState;
    use crate::solvers::{Solver};
use crate::stages::NoProgress;

    #[test]
    fn fingerprint_tells_grids_apart() {
        let a = Scene::default_scene().medium;
        let mut b = a.clone();
        assert_eq!(MediumKey::of(&a), MediumKey::of(&b), "a copy has the same key");
        b.g = 0.5;
        assert_ne!(MediumKey::of(&a), MediumKey::of(&b), "the material is part of the key");
        let one = |v: f32| DensityGrid::from_dense(glam::IVec3::ZERO, glam::IVec3::splat(4), &[v; 64], Default::default()).unwrap();
        assert_eq!(crate::medium::key::grid_fingerprint(&one(1.0)), crate::medium::key::grid_fingerprint(&one(1.0)));
        assert_ne!(crate::medium::key::grid_fingerprint(&one(1.0)), crate::medium::key::grid_fingerprint(&one(1.0 + f32::EPSILON)), "one ulp of density changes the key");
        let mut shifted = a.clone();
        shifted.index_to_world.translation.x += 1e-3;
        assert_ne!(MediumKey::of(&a), MediumKey::of(&shifted), "the transform is part of the key");
    }

    /// Over a session where only the sun moves, the mip, the importance and the dome's
    /// ordinates are built once and reused after; a new density grid or camera position
    /// rebuilds them.
    #[test]
    fn session_reuses_what_only_the_medium_and_camera_decide() {
        let pop = super::super::Pop::from_settings(
            serde_json::json!({"grid_resolution": 12, "output_resolution": 24, "dome_ordinates": 4}).as_object().unwrap(),
        )
        .unwrap();
        let mut scene = Scene::default_scene();
        scene.camera.width = 16;
        scene.camera.height = 16;
        let mut state = SessionState::new();
        for f in 0..3 {
            if let crate::scene::Light::Distant { direction, .. } = &mut scene.lights[0] {
                *direction = glam::Quat::from_rotation_z(0.2 * f as f32) * *direction;
            }
            pop.solve(&scene, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).unwrap();
        }
        let counts = state.kept(PopReuse::default).counts;
        // 4 dome ordinates solved once and reused twice; the sun solved every frame.
        let want = ReuseCounts { mip_reused: 2, mip_built: 1, importance_reused: 2, importance_built: 1, lights_reused: 8, lights_solved: 7 };
        assert_eq!(counts, want);
        scene.camera.position.z += 0.5;
        pop.solve(&scene, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).unwrap();
        let c = state.kept(PopReuse::default).counts;
        assert_eq!((c.mip_reused, c.importance_built), (3, 2), "a moved camera keeps the mip, rebuilds the importance");
        assert_eq!((c.lights_reused, c.lights_solved), (8, 12), "and solves every light again");
        let (lo, _) = scene.medium.grid.bbox();
        scene.medium.grid = DensityGrid::from_dense(lo, glam::IVec3::splat(8), &[0.5; 512], Default::default()).unwrap();
        pop.solve(&scene, &mut SolveCtx::new(&NoProgress).in_session(&mut state)).unwrap();
        let c = state.kept(PopReuse::default).counts;
        assert_eq!((c.mip_built, c.importance_built), (2, 3), "new voxels rebuild both");
    }
}
