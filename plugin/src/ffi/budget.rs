//! The process-wide memory budget (core/src/budget.rs): the largest single buffer volscatter
//! may allocate from input-sized requests. Larger requests fail with `VS_STATUS_TOO_LARGE`
//! before anything is allocated, instead of aborting the host when the allocator gives up.

use super::guard;
use super::status::{FfiError, VsStatus};

/// Sets the memory budget in bytes: no single buffer whose size comes from input (a grid, an
/// image, a decoded map, a solver cache) may be larger. 0 restores the default (a quarter of
/// physical memory, at most half the address-space limit `ulimit -v`). Budgets below 1 MiB are
/// refused with `VS_STATUS_INVALID_ARGUMENT` (nothing useful fits).
///
/// Process-wide, read at each allocation: set it before solving. Thread safety: may be called
/// from any thread at any time.
#[no_mangle]
pub extern "C" fn vs_set_memory_budget(bytes: u64) -> VsStatus {
    guard::call(|| {
        if bytes != 0 && bytes < MIN_BUDGET {
            return Err(FfiError::invalid(format!("memory budget {bytes} bytes is below the minimum of 1 MiB (0 restores the default)")));
        }
        volscatter_core::budget::set_budget((bytes != 0).then_some(bytes));
        Ok(())
    })
}

/// The memory budget now in force, in bytes (the default when none was set).
///
/// Thread safety: may be called from any thread at any time.
#[no_mangle]
pub extern "C" fn vs_memory_budget() -> u64 {
    guard::value(0, volscatter_core::budget::budget)
}

/// Below this nothing a solve needs fits; a smaller number is a mistake (bytes for MiB).
const MIN_BUDGET: u64 = 1 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_round_trips_and_tiny_budgets_are_refused() {
        let default = vs_memory_budget();
        assert!(default > 0);
        assert_eq!(vs_set_memory_budget(12), VsStatus::InvalidArgument);
        assert_eq!(vs_memory_budget(), default, "a refused budget changes nothing");
        assert_eq!(vs_set_memory_budget(0), VsStatus::Ok);
        assert_eq!(vs_memory_budget(), default);
    }
}
