//! The late orders of a medium that scatters for hundreds of them, over fewer directions.
//!
//! In a thick, bright medium (the dense white furnace: thousands of orders to reach
//! `epsilon`) each late order carries a little of the light that has diffused deep inside,
//! and that light is nearly isotropic: a few propagation directions carry it as well as many,
//! at a fraction of the cost (an order's cost is cells x directions). After `FIRST_ORDERS`
//! orders over the solve's directions, which carry the lit skin's detail and the phase
//! function's lobe, the orders go on over `LATE_SIDE`^2 directions a face. U is kept as it
//! is: its storage bins do not depend on the propagation directions. A medium predicted to
//! converge in a usual number of orders never switches (`engaged`), so its solve is the same
//! to the bit. (Coarser cells in place of fewer directions lose light at the medium's
//! boundary: docs/solvers/lpm.md.)

use glam::Vec3;

use super::cost::USUAL_ORDERS;
use super::delta_m::DeltaM;
use super::directions::Directions;
use super::phase_table::PhaseTable;
use crate::error::Result;

/// Orders run over the solve's directions before the late ones take over.
pub const FIRST_ORDERS: usize = 24;

/// Propagation directions of the late orders along a face's side (the `draft` preset's).
pub const LATE_SIDE: u32 = 2;

/// Whether a solve predicted to take `orders` orders (cost.rs) over `dirs` runs its late ones over fewer: twice a usual solve's orders, where
/// those past the first dominate its cost.
pub fn engaged(orders: usize, dirs: &Directions) -> bool {
    orders > 2 * USUAL_ORDERS && dirs.k > LATE_SIDE.max(dirs.s as u32) as usize
}

/// What the late orders' sweeper needs: their directions, the phase table between those and
/// U's storage bins (delta-M scaled as the solve's), and a boundary of no light.
pub struct LateOrders {
    pub dirs: Directions,
    table: PhaseTable,
    pub zero_boundary: Vec<Vec3>,
}

impl LateOrders {
    pub fn new(solve_dirs: &Directions, g: f32, delta: &DeltaM) -> Result<Self> {
        // Never below U's storage side, so that the storage bins stay the same.
        let dirs = Directions::new((LATE_SIDE as usize).max(solve_dirs.s), solve_dirs.s);
        debug_assert_eq!(dirs.storage_solid_angle.len(), solve_dirs.storage_solid_angle.len());
        let truth = PhaseTable::true_phase(&dirs, g)?;
        let table = if delta.active() { delta.table(&dirs, &truth)? } else { truth };
        let zero_boundary = vec![Vec3::ZERO; dirs.len()];
        Ok(LateOrders { dirs, table, zero_boundary })
    }

    pub fn table(&self) -> &PhaseTable {
        &self.table
    }
}
