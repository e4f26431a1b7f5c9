//! What a solver keeps between the frames of a session (pipeline/session.rs says what a
//! session promises): one value of the solver's own type, the single-scattering parts that
//! several solvers share, what changed since the previous frame, and the frame count.

use std::any::Any;

use crate::stages::single_scattering::SingleCache;
use crate::stages::SceneDiff;


/// What a solver keeps between the solves of one session: one value of a type the solver
/// chooses (type-erased, so that the trait stays object-safe and each solver's state private
/// to it), and the count of solves so far.
#[derive(Default)]
pub struct SessionState {
    frame: u64,
    kept: Option<Box<dyn Any + Send>>,
    single: SingleCache,
    diff: Option<SceneDiff>,
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
        self.single = SingleCache::default();
    }

    /// The single-scattering parts kept from the last frame (stages/single_scattering.rs).
    pub fn single(&mut self) -> &mut SingleCache {
        &mut self.single
    }

    /// What changed since the previous frame, when the session's driver said (Session::solve).
    pub fn diff(&self) -> Option<&SceneDiff> {
        self.diff.as_ref()
    }

    /// Set by whoever drives the solves, before the frame's solve.
    pub fn set_diff(&mut self, diff: SceneDiff) {
        self.diff = Some(diff);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
