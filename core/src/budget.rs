//! The memory budget: every allocation whose size comes from input (a file's header, a scene's
//! dims, a solver setting) is computed in checked 64-bit arithmetic and compared with this budget
//! *before* it is made. Rust aborts the whole process when an allocation fails ("memory
//! allocation of N bytes failed" cannot be caught), and inside Blender that kills the artist's
//! session; a refusal that names the input, the size and the budget loses nothing.
//!
//! The budget is per allocation, not a running total: it bounds the largest single buffer, which
//! is what turns a 300-byte hostile header into a 12 GB request. It is process-wide (hosts set it
//! once: `vs_set_memory_budget`, the CLI's `--memory-budget`).
//!
//! Default: a quarter of physical memory, and never more than half of the address-space limit
//! (`ulimit -v`) when one is set, so a refused request is refused by us, not by the allocator.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::{Error, Result};

/// 0 means "not set: use the default".
static BUDGET: AtomicU64 = AtomicU64::new(0);

/// Used when physical memory cannot be read (not Linux): 4 GiB.
const FALLBACK_BYTES: u64 = 4 << 30;

/// The budget in bytes now in force.
pub fn budget() -> u64 {
    match BUDGET.load(Ordering::Relaxed) {
        0 => default_budget(),
        b => b,
    }
}

/// Sets the budget (`None` restores the default). A budget of 0 bytes is not a budget; hosts
/// pass `None` for "default".
pub fn set_budget(bytes: Option<u64>) {
    BUDGET.store(bytes.unwrap_or(0), Ordering::Relaxed);
}

/// The default budget: a quarter of physical memory, at most half the address-space limit.
pub fn default_budget() -> u64 {
    let physical = physical_memory().map(|m| m / 4).unwrap_or(FALLBACK_BYTES);
    match address_space_limit() {
        Some(limit) => physical.min(limit / 2),
        None => physical,
    }
}

/// Refuses `bytes` for `what` when it is over the budget. `what` names the input the size came
/// from ("dome map sky.exr (16384x8192 RGBA f32)", "pop light grid 512^3"), because that is what
/// the user can change.
pub fn check(what: &str, bytes: u64) -> Result<()> {
    let limit = budget();
    if bytes > limit {
        return Err(Error::TooLarge(format!(
            "{what} needs {} but the memory budget is {} (vs_set_memory_budget / --memory-budget)",
            human(bytes),
            human(limit)
        )));
    }
    Ok(())
}

/// `count` elements of `T` for `what`: the byte count in checked arithmetic, then [`check`].
/// Returns the element count as `usize` for the allocation that follows.
pub fn check_elements<T>(what: &str, count: u64) -> Result<usize> {
    let bytes = count
        .checked_mul(std::mem::size_of::<T>() as u64)
        .ok_or_else(|| Error::TooLarge(format!("{what}: {count} elements overflow 64 bits")))?;
    check(what, bytes)?;
    usize::try_from(count).map_err(|_| Error::TooLarge(format!("{what}: {count} elements do not fit this machine's address space")))
}

/// A product of dimensions (voxels, pixels, cells) in checked arithmetic.
pub fn checked_product(what: &str, dims: &[u64]) -> Result<u64> {
    dims.iter()
        .try_fold(1u64, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| Error::TooLarge(format!("{what}: dimensions {dims:?} overflow 64 bits")))
}

/// Bytes as a person reads them (binary units, one decimal).
pub fn human(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 { format!("{bytes} B") } else { format!("{value:.1} {}", UNITS[unit]) }
}

/// MemTotal from /proc/meminfo (Linux); None elsewhere.
fn physical_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The soft "Max address space" limit from /proc/self/limits (what `ulimit -v` sets); None when
/// unlimited or unreadable.
fn address_space_limit() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line.split_whitespace().nth(3)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusal_names_input_size_and_budget() {
        // 1 EiB is over any default budget on any machine that runs these tests.
        let err = check("test grid", 1 << 60).unwrap_err().to_string();
        assert!(err.contains("test grid") && err.contains("1048576.0 TiB") && err.contains("budget"), "{err}");
        assert!(check("small", 1024).is_ok());
    }

    #[test]
    fn element_count_overflow_is_refused_not_wrapped() {
        assert!(check_elements::<[f32; 4]>("cells", u64::MAX / 2).is_err());
        assert!(checked_product("dims", &[1 << 32, 1 << 32, 2]).is_err());
        assert_eq!(checked_product("dims", &[2, 3, 4]).unwrap(), 24);
    }

    #[test]
    fn default_is_a_fraction_of_physical_memory() {
        if let Some(physical) = physical_memory() {
            assert!(default_budget() <= physical / 4);
            assert!(default_budget() > 0);
        }
        assert_eq!(human(1536), "1.5 KiB");
    }
}
