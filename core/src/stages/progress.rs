//! Progress and cancelling, and the time each stage took: what every long stage reports.

use std::time::Instant;

/// Progress reports from a solver; `update` returns false to cancel. Called from the solver's
/// coordinating thread and from worker threads, hence `Sync`.
pub trait Progress: Sync {
    fn update(&self, stage: &str, fraction: f32) -> bool;

    /// True once the host has asked to stop (a cheap flag read, no callback): for loops too
    /// fine-grained to report progress from, which must still stop within ~100 ms of a cancel.
    fn cancelled(&self) -> bool {
        false
    }
}

/// Ignores progress, never cancels.
pub struct NoProgress;
impl Progress for NoProgress {
    fn update(&self, _: &str, _: f32) -> bool {
        true
    }
}

/// Passes a host's cancel through and none of its progress: for a sub-computation (an
/// importance map before the solve proper) whose own stage names would mislead the host.
pub struct CancelOnly<'a>(pub &'a dyn Progress);
impl Progress for CancelOnly<'_> {
    fn update(&self, _: &str, _: f32) -> bool {
        !self.0.cancelled()
    }
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}

/// Wall-clock time of each phase, in seconds, in order.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timings(pub Vec<(String, f64)>);

impl Timings {
    pub fn time<T>(&mut self, phase: &str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let r = f();
        self.0.push((phase.to_string(), t.elapsed().as_secs_f64()));
        r
    }
}
