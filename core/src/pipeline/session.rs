//! Sessions: the solver a host asked for, built once and kept across the solves of a sequence
//! (the frames of a VDB sequence, a moving light or camera) with the state it keeps between
//! them (`SessionState`), so that it may reuse what did not change — POP its density mip, its
//! dome importance and its unchanged distant ordinates (pop/reuse.rs), the network its
//! particles and radiance, the photon grid its ring of partial caches (paper 04).
//!
//! A one-off solve is a session of one frame: the CLI, the C ABI and every host solve through
//! `Session::solve`, which runs the pipeline's steps in order: guard (the scene is one every
//! solver can finish), auto (the solver `auto` picks, rebuilt only when the pick changes),
//! device (the accelerator's backend, or the CPU with a note saying why), solve, guard again
//! (the result is finite).
//!
//! Each frame starts with a scene diff (stages/diff.rs: the medium, each light, the camera,
//! by exact keys), which the solver reads from its state and which decides here: a frame whose
//! scene did not change, or changed only in its camera where the solver's S does not depend on
//! it (`Solver::view_independent`: an isotropic medium), hands back the last frame's S without
//! solving. Below that, the single scattering keeps each light's part while that light, the
//! medium and the camera stay, and its shadow rays' transmittances across a camera move
//! (stages/single_scattering.rs), and each solver what it keeps (across a camera move at
//! g != 0: photon-grid its photons, network its direct light and iteration; see
//! docs/architecture.md for what lpm, pop and vpl solve again and why).
//! Every result's `counters` say what was computed and what was kept.
//!
//! The scene may change in any way between solves. A solver keeps only what it can key on the
//! part of the scene it came from, so a session's answer is the one-off answer, bit for bit
//! (tests below, in pop/reuse.rs and network/session_tests.rs). One declared exception, by the user's choice: `photon-grid` with
//! `generations` m > 1 keeps the paper's temporal ring (photon_grid/ring.rs), whose frames
//! average the last m frames' photons: its first frame is the one-off answer, later ones lag
//! the scene by up to m - 1 frames for 1 / m of the cost.

use std::any::Any;

use serde_json::{Map, Value};

use super::auto::{self, Choice};
use super::device::{Attempt, DeviceUsed, Devices};
use super::guard;
use crate::error::Result;
use crate::scene::Scene;
use crate::solvers::session::SessionState;
use crate::solvers::{registry, SolveCtx, SolveOutput, Solver};
use crate::image::Image;
use crate::stages::diff::SceneKeys;
use crate::stages::{Progress, SceneDiff, ScatteringGrid, Timings};

/// A solve's output and what the pipeline decided on the way.
pub struct Solved {
    pub output: SolveOutput,
    /// What `auto` picked and why (None when a solver was named).
    pub choice: Option<Choice>,
    /// What changed since the session's previous frame (everything on the first).
    pub diff: SceneDiff,
    pub device: DeviceUsed,
    /// What the host should tell the user (a fall-back to the CPU, ...): library code never
    /// prints.
    pub notes: Vec<String>,
}

/// A solver built from its registry name and settings.
pub(crate) struct Built {
    pub name: String,
    pub settings: Map<String, Value>,
    pub solver: Box<dyn Solver>,
}

impl Built {
    fn new(name: &str, settings: &Map<String, Value>) -> Result<Self> {
        Ok(Built { name: name.to_string(), settings: settings.clone(), solver: registry::build(name, settings)? })
    }
}

/// A solver with its settings and devices, and the state it keeps between solves. The solver
/// and its settings are fixed for the session's life; each `solve` takes the scene as it is now.
pub struct Session {
    name: String,
    settings: Map<String, Value>,
    devices: Devices,
    built: Option<Built>,
    state: SessionState,
    /// The last frame's scene keys, and its S and notes while the frame succeeded (None after
    /// a failed or cancelled frame: the next one solves).
    last: Option<(SceneKeys, Option<(ScatteringGrid, Vec<String>, DeviceUsed)>)>,
}

impl Session {
    /// A session of solver `name` (a registry name, `auto` included) with `settings` (the
    /// scene's `solver` block), validated now: unknown names and bad settings are refused here.
    pub fn new(name: &str, settings: &Map<String, Value>, devices: Devices) -> Result<Self> {
        let built = if name == auto::NAME {
            auto::validate(settings)?;
            None
        } else {
            Some(Built::new(name, settings)?)
        };
        Ok(Session { name: name.to_string(), settings: settings.clone(), devices, built, state: SessionState::new(), last: None })
    }

    /// A session of the solver `scene` names (default "reference"), with its settings.
    pub fn for_scene(scene: &Scene, devices: Devices) -> Result<Self> {
        Session::new(scene.solver_name().unwrap_or("reference"), &scene.solver, devices)
    }

    pub fn name(&self) -> &str {
        &self.name
    }
    pub fn settings(&self) -> &Map<String, Value> {
        &self.settings
    }
    pub fn devices(&self) -> Devices {
        self.devices
    }
    /// Solves done (or attempted) in this session.
    pub fn frames(&self) -> u64 {
        self.state.frames()
    }

    /// Builds the solver for `scene` when it is not built yet: for `auto`, its pick for this
    /// scene (kept while the pick stays the same, so that the picked solver keeps its reuse).
    fn pick(&mut self, scene: &Scene) -> Result<Option<Choice>> {
        if self.name != auto::NAME {
            return Ok(None);
        }
        let c = auto::choose(scene, &self.settings, registry::preset_settings)?;
        if !self.built.as_ref().is_some_and(|b| b.name == c.solver && b.settings == c.settings) {
            self.built = Some(Built::new(&c.solver, &c.settings)?);
            // Another solver: nothing of the last frame's S carries over.
            self.last = None;
        }
        Ok(Some(c))
    }

    /// Starts a frame: counts it, guards the scene, builds `auto`'s pick for it, and tells the
    /// solver's state what changed since the last frame.
    fn begin(&mut self, scene: &Scene) -> Result<(Option<Choice>, SceneDiff)> {
        self.state.begin_frame();
        let last = self.last.take();
        guard::check_scene(scene)?;
        let choice = self.pick(scene)?;
        let keys = SceneKeys::of(scene);
        let (diff, kept) = match (last, &self.last) {
            // `pick` left `last` empty: the same solver as the last frame.
            (Some((before, kept)), None) => (SceneDiff::between(&before, &keys), kept),
            _ => (SceneDiff::first(scene.lights.len()), None),
        };
        self.state.set_diff(diff.clone());
        self.last = Some((keys, kept));
        Ok((choice, diff))
    }

    /// Solves `scene`, reusing what the previous solves kept.
    pub fn solve(&mut self, scene: &Scene, progress: &dyn Progress) -> Result<Solved> {
        let (choice, diff) = self.begin(scene)?;
        self.run(scene, progress, choice, diff)
    }

    /// One frame for an image: the solver's own image when it renders images (the path
    /// tracer), else its solve (for the pipeline to composite). Guarded and picked once.
    pub(crate) fn render_frame(&mut self, scene: &Scene, progress: &dyn Progress, transparent: bool) -> Result<Frame> {
        let (choice, diff) = self.begin(scene)?;
        {
            let Session { built, state, .. } = &mut *self;
            let Some(built) = built.as_ref() else { unreachable!("a session's solver is built before it solves") };
            let mut timings = Timings::default();
            let mut ctx = SolveCtx::new(progress).in_session(state);
            if let Some(image) = built.solver.render_image(scene, &mut ctx, transparent, &mut timings) {
                let image = image?;
                guard::check_finite(scene, "image", image.rgba.iter().map(|p| p.truncate()).chain(image.aovs.iter().flat_map(|a| a.1.iter().copied())))?;
                return Ok(Frame::Image { image, timings, notes: scene.notes() });
            }
        }
        self.run(scene, progress, choice, diff).map(Frame::Solved)
    }

    /// The device step and the solve of a begun frame, and the check of its result.
    fn run(&mut self, scene: &Scene, progress: &dyn Progress, choice: Option<Choice>, diff: SceneDiff) -> Result<Solved> {
        let Session { devices, built, state, last, .. } = self;
        // Built in `new` for every name but auto, and by `pick` for auto.
        let Some(built) = built.as_ref() else { unreachable!("a session's solver is built before it solves") };
        // A solver whose scattering grid is wildly off on this scene refuses it, naming the
        // solvers to use (auto never picks one that does). Here, not in `begin`: the path
        // tracer's own image is right where its grid is refused.
        crate::solvers::limits::check_scene(&built.name, scene)?;
        let Some((_, kept)) = last.as_mut() else { unreachable!("`begin` keeps the frame's keys") };
        let same_s = diff.nothing() || (diff.camera_only() && built.solver.view_independent(scene));
        match kept.take() {
            Some((s, notes, device)) if same_s && built.solver.repeatable() => {
                let mut output = SolveOutput::new(s.clone(), Timings(vec![("reuse S".into(), 0.0)]));
                output.counters.kept("solve");
                *kept = Some((s, notes.clone(), device.clone()));
                return Ok(Solved { output, choice, diff, device, notes });
            }
            _ => {}
        }
        let mut notes = scene.notes();
        let mut solve = |backend: Option<&dyn Any>| {
            let ctx = SolveCtx::new(progress).in_session(state);
            let mut ctx = match backend {
                Some(b) => ctx.on(b),
                None => ctx,
            };
            built.solver.solve(scene, &mut ctx)
        };
        let accelerated = devices.accelerator.is_some_and(|a| a.has_backend(&built.name));
        let (output, device) = devices.run(&mut notes, accelerated, |on| match on {
            Some((accelerator, choice)) => accelerator.solve(choice, &built.name, &mut |backend| solve(Some(backend))),
            None => solve(None).map(|out| Attempt::Ran(out, DeviceUsed::Cpu)),
        })?;
        notes.extend(output.notes.iter().cloned());
        guard::check_finite(scene, "scattering grid", output.scattering.data.iter().copied())?;
        if built.solver.repeatable() {
            *kept = Some((output.scattering.clone(), notes.clone(), device.clone()));
        }
        Ok(Solved { output, choice, diff, device, notes })
    }

    /// The solver built for the last frame (for `auto`, its last pick), if any.
    pub fn solver(&self) -> Option<&dyn Solver> {
        self.built.as_ref().map(|b| b.solver.as_ref())
    }
}

/// What one frame of `render_frame` gave.
pub(crate) enum Frame {
    /// The solver's own image (checked finite), its stages' times and what loading the scene noted.
    Image { image: Image, timings: Timings, notes: Vec<String> },
    Solved(Solved),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Devices;
    use crate::scene::Light;
    use crate::solvers::registry;
    use crate::stages::NoProgress;
    use glam::Vec3;

    fn bits(out: &SolveOutput) -> Vec<[u32; 3]> {
        out.scattering.data.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
    }

    /// The default scene with its plume at `n`^3 voxels and the camera `lift` m higher, its
    /// sun turned by `step` x 0.3 radians about z.
    fn frame(step: usize, n: u32, lift: f32, solver: &serde_json::Value) -> Scene {
        let json = crate::scene::DEFAULT_SCENE_JSON.replace(r#""dims": [64]"#, &format!(r#""dims": [{n}]"#));
        let mut scene = Scene::from_json_str(&json, std::path::Path::new(".")).unwrap();
        scene.solver = solver.as_object().cloned().unwrap_or_default();
        scene.camera.width = 16;
        scene.camera.height = 16;
        scene.camera.position.z += lift;
        for l in &mut scene.lights {
            if let Light::Distant { direction, .. } = l {
                *direction = glam::Quat::from_rotation_z(0.3 * step as f32) * *direction;
            }
        }
        scene
    }

    /// A solver that keeps nothing (the reference) answers in a session exactly as one-off:
    /// with a fixed seed, every frame of a session is bit-identical to its one-off solve.
    #[test]
    fn reference_in_a_session_is_bit_identical_to_one_off() {
        let settings = serde_json::json!({"name": "reference", "seed": 7, "spp": 4, "grid_resolution": 8});
        let mut session = Session::for_scene(&frame(0, 16, 0.0, &settings), Devices::cpu()).unwrap();
        for f in 0..3 {
            let scene = frame(f, 16, 0.0, &settings);
            let one_off = registry::build("reference", &scene.solver).unwrap().solve(&scene, &mut SolveCtx::new(&NoProgress)).unwrap();
            let kept = session.solve(&scene, &NoProgress).unwrap().output;
            assert_eq!(bits(&kept), bits(&one_off), "frame {f}");
        }
        assert_eq!(session.frames(), 3);
    }

    /// POP across frames where nothing is reusable (the medium's voxels and the camera change
    /// every frame, so neither the density mip, the dome importance nor any ordinate may be
    /// reused) and
    /// where only the sun moves (both reused): bit-identical to one-off solves either way.
    #[test]
    fn pop_in_a_session_is_bit_identical_to_one_off() {
        let settings = serde_json::json!({"name": "pop", "grid_resolution": 12, "output_resolution": 24, "dome_ordinates": 4});
        for change_all in [true, false] {
            let mut session = Session::for_scene(&frame(0, 16, 0.0, &settings), Devices::cpu()).unwrap();
            for f in 0..3 {
                let scene = if change_all { frame(f, 16 + 4 * f as u32, 0.5 * f as f32, &settings) } else { frame(f, 16, 0.0, &settings) };
                let one_off = registry::build("pop", &scene.solver).unwrap().solve(&scene, &mut SolveCtx::new(&NoProgress)).unwrap();
                let kept = session.solve(&scene, &NoProgress).unwrap().output;
                assert!(kept.scattering.data.iter().any(|v| *v != Vec3::ZERO), "frame {f} lit");
                assert_eq!(bits(&kept), bits(&one_off), "frame {f}, everything changing: {change_all}");
            }
        }
    }
}
