//! What a frame did besides its stages' times: which stages it computed and which it kept
//! from an earlier frame of its session, and on a device what it created and moved. Every
//! `SolveOutput` carries them, so that tests and benchmarks assert reuse instead of timing it.

/// Counts of one solve (a frame of a session, or a one-off solve).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    /// Stages (or parts of one: "single scattering: light 1") computed in this frame, in order.
    pub recomputed: Vec<String>,
    /// Stages kept from an earlier frame of the session, in order.
    pub reused: Vec<String>,
    /// Bytes written to a device's buffers.
    pub bytes_uploaded: u64,
    /// Bytes read back from a device.
    pub bytes_read_back: u64,
    /// Compute pipelines compiled.
    pub pipelines_created: u64,
    /// Device buffers allocated.
    pub buffers_created: u64,
    /// Command buffers submitted to a device's queue.
    pub submissions: u64,
}

impl Counters {
    pub fn computed(&mut self, stage: impl Into<String>) {
        self.recomputed.push(stage.into());
    }

    pub fn kept(&mut self, stage: impl Into<String>) {
        self.reused.push(stage.into());
    }

    /// Whether `stage` was computed in this frame (by exact name, or a part of it: "stage: ...").
    pub fn was_computed(&self, stage: &str) -> bool {
        self.recomputed.iter().any(|s| names(s, stage))
    }

    /// Whether `stage` was kept from an earlier frame (exact name or a part of it).
    pub fn was_reused(&self, stage: &str) -> bool {
        self.reused.iter().any(|s| names(s, stage))
    }

    /// Adds `other`'s counts to these (a solve's sub-steps, a device's counts).
    pub fn add(&mut self, other: &Counters) {
        self.recomputed.extend(other.recomputed.iter().cloned());
        self.reused.extend(other.reused.iter().cloned());
        self.bytes_uploaded += other.bytes_uploaded;
        self.bytes_read_back += other.bytes_read_back;
        self.pipelines_created += other.pipelines_created;
        self.buffers_created += other.buffers_created;
        self.submissions += other.submissions;
    }
}

fn names(s: &str, stage: &str) -> bool {
    s == stage || s.strip_prefix(stage).is_some_and(|rest| rest.starts_with(": "))
}
