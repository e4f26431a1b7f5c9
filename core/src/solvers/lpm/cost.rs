//! The cost guard of lpm: its work is cells x directions x orders, and the orders are the
//! medium's to decide: a thick, white medium keeps scattering light for hundreds of orders
//! before the last falls below `epsilon`. Before the orders run, the solve predicts their
//! number from the medium's optical thickness and albedo; past twice a usual solve's the late
//! orders run over fewer directions (coarse.rs) and end on their geometric tail (tail.rs),
//! and where they cannot, a solve far beyond a usual one says so up front (the progress
//! stage's text, which a host shows while it waits) and in a note.

use glam::Vec3;

use super::grid::LpmGrid;

/// Orders of a usual solve (a cloud of albedo 0.9, optical depth 5: about 40 by the model
/// below); the note is given past 4x that.
pub const USUAL_ORDERS: usize = 40;

/// The predicted number of orders and the optical thickness it came from. Diffusion's slowest
/// mode in a slab of transport optical thickness tau (extrapolated by 0.71 a side) loses
/// 1 / (1 + (pi / (tau + 1.42))^2 / 3) of its light per scattering at albedo 1, so an order's
/// largest U falls by `lambda` = albedo times that, and reaches `epsilon` after
/// ln(epsilon) / ln(lambda) orders. tau: the occupied cells' mean extinction (channel mean)
/// times the grid's shortest side, under the similarity (1 - albedo g).
pub fn predicted_orders(grid: &LpmGrid, albedo: Vec3, g: f32, epsilon: f32, max_orders: u32) -> (usize, f32) {
    let (sum, n) = grid.sigma_t.iter().map(|s| s.element_sum() / 3.0).filter(|s| *s > 0.0).fold((0.0f64, 0usize), |(a, k), s| (a + s as f64, k + 1));
    if n == 0 {
        return (1, 0.0);
    }
    let a = (albedo.element_sum() / 3.0).clamp(0.0, 1.0);
    let side = grid.dims.iter().copied().min().unwrap_or(1) as f32 * grid.h;
    let tau = (sum / n as f64) as f32 * side * (1.0 - a * g.clamp(-1.0, 1.0)).max(0.0);
    let lambda = a / (1.0 + (std::f32::consts::PI / (tau + 1.42)).powi(2) / 3.0);
    let orders = if lambda <= 0.0 { 1.0 } else { (epsilon.ln() / lambda.ln()).ceil() + 1.0 };
    ((orders.max(1.0) as usize).min(max_orders as usize), tau)
}

/// The note when `orders` is far beyond a usual solve's, else None.
pub fn note(orders: usize, tau: f32, albedo: Vec3, cells: usize, directions: usize) -> Option<String> {
    (orders > 4 * USUAL_ORDERS).then(|| {
        format!(
            "lpm: this medium (optical thickness about {tau:.0}, albedo {:.2}) needs about {orders} scattering orders of \
             {cells} cells x {directions} directions, {:.0}x a usual solve's: expect minutes; pop, or a lower max_orders \
             or larger epsilon, are faster",
            albedo.element_sum() / 3.0,
            orders as f32 / USUAL_ORDERS as f32
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(sigma_t: f32) -> LpmGrid {
        let n = 16usize;
        LpmGrid { dims: [n; 3], lo: Vec3::ZERO, h: 1.0 / n as f32, offset: [0; 3], density: vec![1.0; n * n * n], sigma_t: vec![Vec3::splat(sigma_t); n * n * n] }
    }

    /// The dense white furnace (optical thickness 40, albedo 1) is predicted to need the whole
    /// cap of 200 orders and gets the note; a cloud (5, albedo 0.9) about 40 orders and none.
    #[test]
    fn harden_lpm_predicts_a_white_furnace_slow_and_a_cloud_usual() {
        let (orders, tau) = predicted_orders(&grid(40.0), Vec3::ONE, 0.0, 1e-3, 200);
        assert_eq!(orders, 200, "tau {tau}");
        assert!(note(orders, tau, Vec3::ONE, 4096, 150).is_some_and(|n| n.contains("200 scattering orders")));
        let (orders, _) = predicted_orders(&grid(5.0), Vec3::splat(0.9), 0.0, 1e-3, 200);
        // The model's 39 for this cloud; 10 either way is within what it claims.
        assert!((30..=50).contains(&orders), "{orders}");
        assert!(note(orders, 5.0, Vec3::splat(0.9), 4096, 150).is_none());
    }
}
