//! Progress on stderr: one line per stage, rewritten in place, at most ~10 updates a second.

use std::io::Write;
use std::sync::Mutex;
use std::time::Instant;
use volscatter_core::Progress;

pub struct StderrProgress {
    state: Mutex<(Instant, String)>,
    quiet: bool,
}

impl StderrProgress {
    pub fn new(quiet: bool) -> Self {
        StderrProgress { state: Mutex::new((Instant::now(), String::new())), quiet }
    }
    pub fn finish(&self) {
        if !self.quiet {
            eprintln!();
        }
    }
}

impl Progress for StderrProgress {
    fn update(&self, stage: &str, fraction: f32) -> bool {
        if self.cancelled() {
            return false;
        }
        if self.quiet {
            return true;
        }
        let Ok(mut st) = self.state.lock() else { return true };
        let new_stage = st.1 != stage;
        if new_stage || st.0.elapsed().as_millis() >= 100 || fraction >= 1.0 {
            if new_stage && !st.1.is_empty() {
                eprintln!();
            }
            eprint!("\r{stage}: {:5.1}%", fraction * 100.0);
            let _ = std::io::stderr().flush();
            st.0 = Instant::now();
            st.1 = stage.to_string();
        }
        true
    }

    /// A signal (cli/signals.rs) cancels the solve.
    fn cancelled(&self) -> bool {
        super::signals::received().is_some()
    }
}
