//! Sessions (issue 14): one solver kept across the solves of a sequence (the frames of a VDB
//! sequence, a moving light or camera), so that it may reuse between frames what did not
//! change — POP its density mip, its dome importance and its unchanged distant ordinates
//! (pop/reuse.rs); later, the photon
//! grid's ring of partial caches (paper 04) or the network's warm start (paper 02).
//!
//! The scene may change in any way between solves. A solver keeps only what it can key on
//! the part of the scene it came from, and recomputes what no longer matches, so a session's
//! answer is the one-off answer: `Solver::solve_in_session` defaults to `solve`, and POP's
//! reuse returns the very values it would recompute (tests below and in pop/reuse.rs).
//!
//! One declared exception, by the user's choice: `photon-grid` with `generations` m > 1 keeps
//! the paper's temporal ring (photon_grid/ring.rs), whose frames average the last m frames'
//! photons: its first frame is the one-off answer, later ones lag the scene by up to m - 1
//! frames for 1 / m of the cost (with m = 1, the default, it keeps the contract).

use std::any::Any;

use super::{by_name, Progress, SolveOutput, Solver};
use crate::error::Result;
use crate::scene::Scene;

/// What a solver keeps between the solves of one session: one value of a type the solver
/// chooses (type-erased, so that the trait stays object-safe and each solver's state private
/// to it), and the count of solves so far.
#[derive(Default)]
pub struct SessionState {
    frame: u64,
    kept: Option<Box<dyn Any + Send>>,
}

impl SessionState {
    pub fn new() -> Self {
        Self::default()
    }

    /// Solves started in this state so far (the frame index of the solve under way, from 0,
    /// once `begin_frame` has been called for it).
    pub fn frames(&self) -> u64 {
        self.frame
    }

    /// Counts one more solve; returns its index from 0. Called by whoever drives the solves
    /// (`Session::solve`, the GPU dispatch), not by solvers.
    pub fn begin_frame(&mut self) -> u64 {
        self.frame += 1;
        self.frame - 1
    }

    /// The solver's kept value of type `T`, made by `make` on first use, or when the value
    /// kept is of another type (another solver used this state before).
    pub fn kept<T: Any + Send>(&mut self, make: impl FnOnce() -> T) -> &mut T {
        if !self.kept.as_ref().is_some_and(|k| k.is::<T>()) {
            self.kept = Some(Box::new(make()));
        }
        match self.kept.as_mut().and_then(|k| k.downcast_mut::<T>()) {
            Some(t) => t,
            // Set just above with a `T`; reached only if that invariant breaks.
            None => unreachable!("session state holds the type just stored"),
        }
    }

    /// Drops what the solver kept (the frame count stays).
    pub fn clear(&mut self) {
        self.kept = None;
    }
}

/// A solver with its settings and the state it keeps between solves. The solver and its
/// settings are fixed for the session's life; each `solve` takes the scene as it is now.
pub struct Session {
    name: String,
    settings: serde_json::Map<String, serde_json::Value>,
    solver: Box<dyn Solver>,
    state: SessionState,
}

impl Session {
    /// A session of solver `name` with `settings` (the scene's `solver` block), validated now.
    pub fn new(name: &str, settings: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        let solver = by_name(name, settings)?;
        Ok(Session { name: name.to_string(), settings: settings.clone(), solver, state: SessionState::new() })
    }

    /// A session of the solver `scene` names (default "reference"), with its settings.
    pub fn for_scene(scene: &Scene) -> Result<Self> {
        Session::new(scene.solver_name().unwrap_or("reference"), &scene.solver)
    }

    pub fn name(&self) -> &str {
        &self.name
    }
    pub fn settings(&self) -> &serde_json::Map<String, serde_json::Value> {
        &self.settings
    }
    /// Solves done (or attempted) in this session.
    pub fn frames(&self) -> u64 {
        self.state.frames()
    }
    /// The kept state, for drivers that run the solver elsewhere (the GPU dispatch of
    /// volscatter-gpu builds its own solver from `name` and `settings`).
    pub fn state_mut(&mut self) -> &mut SessionState {
        &mut self.state
    }

    /// Solves `scene` on the CPU, reusing what the previous solves kept.
    pub fn solve(&mut self, scene: &Scene, progress: &dyn Progress) -> Result<SolveOutput> {
        self.state.begin_frame();
        super::guard::check_scene(scene)?;
        let out = self.solver.solve_in_session(scene, progress, &mut self.state)?;
        super::guard::check_finite(scene, "scattering grid", out.scattering.data.iter().copied())?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Light;
    use crate::solvers::NoProgress;
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

    #[test]
    fn kept_value_is_replaced_when_its_type_changes() {
        let mut st = SessionState::new();
        *st.kept(|| 1u32) += 1;
        assert_eq!(*st.kept(|| 0u32), 2, "a kept value of the same type is handed back");
        assert_eq!(*st.kept(|| 7u64), 7, "a value of another type replaces it");
        st.clear();
        assert_eq!(*st.kept(|| 3u64), 3);
        assert_eq!(st.begin_frame(), 0);
        assert_eq!(st.begin_frame(), 1);
        assert_eq!(st.frames(), 2);
    }

    /// A solver that keeps nothing (the reference) answers in a session exactly as one-off:
    /// with a fixed seed, every frame of a session is bit-identical to its one-off solve.
    #[test]
    fn reference_in_a_session_is_bit_identical_to_one_off() {
        let settings = serde_json::json!({"name": "reference", "seed": 7, "spp": 4, "grid_resolution": 8});
        let mut session = Session::for_scene(&frame(0, 16, 0.0, &settings)).unwrap();
        for f in 0..3 {
            let scene = frame(f, 16, 0.0, &settings);
            let one_off = by_name("reference", &scene.solver).unwrap().solve(&scene, &NoProgress).unwrap();
            let kept = session.solve(&scene, &NoProgress).unwrap();
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
            let mut session = Session::for_scene(&frame(0, 16, 0.0, &settings)).unwrap();
            for f in 0..3 {
                let scene = if change_all { frame(f, 16 + 4 * f as u32, 0.5 * f as f32, &settings) } else { frame(f, 16, 0.0, &settings) };
                let one_off = by_name("pop", &scene.solver).unwrap().solve(&scene, &NoProgress).unwrap();
                let kept = session.solve(&scene, &NoProgress).unwrap();
                assert!(kept.scattering.data.iter().any(|v| *v != Vec3::ZERO), "frame {f} lit");
                assert_eq!(bits(&kept), bits(&one_off), "frame {f}, everything changing: {change_all}");
            }
        }
    }
}
