//! Geometric optics of the medium that every solver and the compositor share: the ray/box
//! slab test, deterministic optical depth by quadrature, the corners of an index box placed in
//! the world, and the ball kernel that spreads a point emitter's 1/d^2 over a ball. They live
//! here, not in the compositor, so that solvers need not import the compositor (which imports
//! the solvers' scattering grid).

use glam::{Affine3A, Vec3};

use super::Medium;

/// Ray/box intersection; returns the parameter range inside, if any, clipped to t >= 0. A
/// component of NaN (a ray parallel to and on a slab boundary: 0 * inf) does not constrain.
pub fn ray_box(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let inv = d.recip();
    let a = (lo - o) * inv;
    let b = (hi - o) * inv;
    // Masked before any min/max: glam's min and max drop a NaN operand, which would turn the
    // NaN slab into a bound of -inf or +inf instead of no bound.
    let nan = a.is_nan_mask() | b.is_nan_mask();
    let t0 = Vec3::select(nan, Vec3::NEG_INFINITY, a.min(b)).max_element().max(0.0);
    let t1 = Vec3::select(nan, Vec3::INFINITY, a.max(b)).min_element();
    (t0 < t1).then_some((t0, t1))
}

/// Deterministic optical depth (RGB) from `x` along unit `d` over at most `t_max`, by midpoint
/// quadrature with at most `max_steps` steps of at least `min_step`.
pub fn optical_depth(medium: &Medium, x: Vec3, d: Vec3, t_max: f32, min_step: f32, max_steps: u32) -> Vec3 {
    let (lo, hi) = medium.world_bounds();
    let Some((t0, t1)) = ray_box(x, d, lo, hi) else { return Vec3::ZERO };
    let t1 = t1.min(t_max);
    if t1 <= t0 {
        return Vec3::ZERO;
    }
    let n = (((t1 - t0) / min_step).ceil() as u32).clamp(1, max_steps);
    let h = (t1 - t0) / n as f32;
    let mut tau = 0.0;
    for i in 0..n {
        tau += medium.density_world(x + d * (t0 + (i as f32 + 0.5) * h));
    }
    medium.density_scale * tau * h
}

/// The 8 corners of the box [lo, hi] (x fastest), each through `map`.
pub fn box_corners(lo: Vec3, hi: Vec3, map: impl Fn(Vec3) -> Vec3) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        map(Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        ))
    })
}

/// Axis-aligned world box containing the index-space box [lo, hi] placed by `index_to_world`.
/// A plain loop rather than `box_corners`: optical_depth asks for the medium's box on every
/// shadow ray, millions of times per single-scattering grid.
pub fn world_box(index_to_world: &Affine3A, lo: Vec3, hi: Vec3) -> (Vec3, Vec3) {
    let mut wmin = Vec3::splat(f32::INFINITY);
    let mut wmax = Vec3::splat(f32::NEG_INFINITY);
    for i in 0..8 {
        let c = Vec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), hi, lo);
        let w = index_to_world.transform_point3(c);
        wmin = wmin.min(w);
        wmax = wmax.max(w);
    }
    (wmin, wmax)
}

/// The smallest spacing of a grid placed by `index_to_world` along its three axes.
pub fn min_spacing(index_to_world: &Affine3A) -> f32 {
    let m = index_to_world.matrix3;
    m.x_axis.length().min(m.y_axis.length()).min(m.z_axis.length())
}

/// A grid holding point samples of a field that is interpolated trilinearly must carry, at a
/// grid point, the mean of the field around it, not its value at the point, or an emitter
/// inside the medium (1/d^2) is over- or under-counted by where it falls between grid points.
/// Returns the radius of the ball with the volume of one cell of the grid placed by
/// `index_to_world`, (3 h^3 / 4 pi)^(1/3).
pub fn near_field_radius(index_to_world: &Affine3A) -> f32 {
    let volume = glam::Mat3::from(index_to_world.matrix3).determinant().abs();
    (3.0 * volume / (4.0 * std::f32::consts::PI)).cbrt()
}

/// The mean of 1/|y|^2 over a ball of radius `r` whose centre is at distance `d` from the
/// origin: (3 / (2 r^3 d)) ((r^2 - d^2)/2 ln((r + d)/|r - d|) + d r). It is 3/r^2 at d = 0,
/// bounded, and 1/d^2 (1 + x^2/5 + 3 x^4/35 + x^6/21 + ...), x = r/d, far away (the series is
/// used for x < 1/4, where the closed form cancels; truncation error < 1e-5). Its integral
/// over all space equals that of 1/d^2: it spreads a point emitter's near field without losing
/// energy (a sphere light's radius enters too: outside it the kernel is 1/d^2 within r^2/5d^2).
#[inline]
pub fn ball_mean_inverse_square(d: f32, r: f32) -> f32 {
    if r <= 0.0 {
        return 1.0 / (d * d);
    }
    if d < 1e-4 * r {
        return 3.0 / (r * r);
    }
    let x = r / d;
    if x < 0.25 {
        let x2 = x * x;
        return (1.0 + x2 * (0.2 + x2 * (3.0 / 35.0 + x2 / 21.0))) / (d * d);
    }
    let gap = (r - d).abs().max(1e-7 * r);
    1.5 / (r * r * r * d) * (0.5 * (r * r - d * d) * ((r + d) / gap).ln() + d * r)
}

/// How a lamp of radius `lamp` lights a point at distance `d` from its centre, per W/sr of its
/// intensity: the point lamp's 1/d^2; for a sphere lamp (docs/scene-format.md) the solid angle
/// its surface subtends times its radiance 1/(pi r^2), inside it nothing (`lit` false) or its
/// surface's value 2/r^2 (`lit`: half that radiance from every direction, as Cycles lights it). `near` > 0 spreads the field over a ball of
/// that radius (a grid cell, a solver's near field); a lamp smaller than that is a ball too
/// (`ball_mean_inverse_square`, which keeps the power: its inside cannot be resolved), and a
/// lit interior's added light, 2/r^2 over the sphere's volume, is spread evenly over that ball.
#[inline]
pub fn lamp_inverse_square(d: f32, lamp: f32, near: f32, lit: bool) -> f32 {
    if lamp <= near {
        let ball = (lamp * lamp + near * near).sqrt();
        let interior = if lit && d < ball { 2.0 * lamp / (ball * ball * ball) } else { 0.0 };
        return ball_mean_inverse_square(d, ball) + interior;
    }
    if d < lamp {
        return if lit { 2.0 / (lamp * lamp) } else { 0.0 };
    }
    let sin2 = (lamp * lamp / (d * d)).min(1.0);
    // 1 - cos of the subtended half-angle, by its series where it would cancel.
    let one_minus_cos = if sin2 < 1e-3 { 0.5 * sin2 + 0.125 * sin2 * sin2 } else { 1.0 - (1.0 - sin2).sqrt() };
    2.0 * one_minus_cos / (lamp * lamp)
}

/// The mean of `lamp_inverse_square(|y|, lamp, 0, lit)` over a ball of radius `ball` whose
/// centre is at distance `d` from the lamp's: what a cell of that volume gets on average near a
/// sphere lamp, where the value at its centre would see the surface up close or miss it (a
/// solve's brightness near a lamp would then hang on where its cell centres fall). By shells
/// about the lamp, each weighted by its area inside the ball, split at the lamp's surface
/// where the field jumps; past `NEAR_BALLS` balls from the surface, the value at the centre
/// (within ball^2 / 5d^2 of the mean, as `ball_mean_inverse_square`).
pub fn lamp_mean_over_ball(d: f32, lamp: f32, ball: f32, lit: bool) -> f32 {
    const NEAR_BALLS: f32 = 4.0;
    const STEPS: usize = 16;
    if ball <= 0.0 || d >= lamp + NEAR_BALLS * ball {
        return lamp_inverse_square(d, lamp, 0.0, lit);
    }
    let (lo, hi) = ((d - ball).max(0.0), d + ball);
    // The area of the shell of radius s (about the lamp) inside the ball.
    let area = |s: f32| if s <= ball - d { 4.0 * std::f32::consts::PI * s * s } else { std::f32::consts::PI * s * (ball * ball - (s - d) * (s - d)).max(0.0) / d.max(1e-12) };
    let mut sum = 0.0f64;
    let cuts = if lo < lamp && lamp < hi { [lo, lamp, hi] } else { [lo, lo, hi] };
    for w in cuts.windows(2) {
        let ds = (w[1] - w[0]) / STEPS as f32;
        for k in 0..STEPS {
            let s = w[0] + (k as f32 + 0.5) * ds;
            sum += (lamp_inverse_square(s, lamp, 0.0, lit) * area(s) * ds) as f64;
        }
    }
    (sum / (4.0 / 3.0 * std::f64::consts::PI * (ball as f64).powi(3))) as f32
}

/// Tests' reference for the means over a ball: the mean of `f(|y|)` over the points of an
/// n^3 lattice in the ball of radius `radius` about (d, 0, 0).
#[cfg(test)]
pub(crate) fn lattice_mean_over_ball(n: usize, d: f32, radius: f32, f: impl Fn(f32) -> f64) -> f64 {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let q = (Vec3::new(i as f32, j as f32, k as f32) + 0.5) / n as f32 * 2.0 - 1.0;
                if q.length() <= 1.0 {
                    sum += f((Vec3::new(d, 0.0, 0.0) + q * radius).length());
                    count += 1;
                }
            }
        }
    }
    sum / count as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Near a sphere lamp the ball's mean against the mean over the points of a 64^3 lattice
    /// in the ball, within 2% (16 midpoint steps a side of the surface); far away the value at
    /// the centre; a ball inside a dark lamp gets nothing.
    #[test]
    fn lamp_mean_over_ball_is_the_cells_mean() {
        let (lamp, ball) = (0.08f32, 0.031f32);
        let lattice = |d: f32, lit: bool| lattice_mean_over_ball(64, d, ball, |s| lamp_inverse_square(s, lamp, 0.0, lit) as f64) as f32;
        for (d, lit) in [(0.07f32, false), (0.08, false), (0.09, false), (0.11, false), (0.0, true), (0.06, true), (0.1, true)] {
            let (got, want) = (lamp_mean_over_ball(d, lamp, ball, lit), lattice(d, lit));
            assert!((got / want - 1.0).abs() < 0.02, "d {d} lit {lit}: {got} against {want}");
        }
        assert_eq!(lamp_mean_over_ball(1.0, lamp, ball, false), lamp_inverse_square(1.0, lamp, 0.0, false));
        assert_eq!(lamp_mean_over_ball(0.02, lamp, ball, false), 0.0);
    }

    /// Rays from inside, outside, missing, and parallel to a face (NaN slabs): exact
    /// parameters (the box edges are powers of two, so no rounding).
    #[test]
    fn ray_box_cases() {
        let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        assert_eq!(ray_box(Vec3::new(-4.0, 0.0, 0.0), Vec3::X, lo, hi), Some((3.0, 5.0)));
        assert_eq!(ray_box(Vec3::ZERO, Vec3::X, lo, hi), Some((0.0, 1.0)));
        assert_eq!(ray_box(Vec3::new(-4.0, 2.0, 0.0), Vec3::X, lo, hi), None);
        assert_eq!(ray_box(Vec3::new(2.0, 0.0, 0.0), Vec3::X, lo, hi), None);
        // On the face y = 1, parallel to it: (1 - 1) * inf is NaN and must not reject the ray.
        assert_eq!(ray_box(Vec3::new(-4.0, 1.0, 0.0), Vec3::X, lo, hi), Some((3.0, 5.0)));
    }

    /// The world box of a rotated unit cube is the rotated corners' hull: for 45 degrees about
    /// z, x and y span +-sqrt 2 (to 1e-6, the rotation's rounding).
    #[test]
    fn world_box_of_rotated_cube() {
        let m = Affine3A::from_rotation_z(std::f32::consts::FRAC_PI_4);
        let (lo, hi) = world_box(&m, Vec3::splat(-1.0), Vec3::splat(1.0));
        let s = std::f32::consts::SQRT_2;
        assert!((lo - Vec3::new(-s, -s, -1.0)).abs().max_element() < 1e-6, "{lo}");
        assert!((hi - Vec3::new(s, s, 1.0)).abs().max_element() < 1e-6, "{hi}");
    }

    /// A cell of 0.1^3 m^3 has the volume of a ball of radius (3e-3 / 4 pi)^(1/3) = 0.0620.
    #[test]
    fn near_field_radius_has_the_cell_volume() {
        let r = near_field_radius(&Affine3A::from_scale(Vec3::splat(0.1)));
        assert!((4.0 / 3.0 * std::f32::consts::PI * r * r * r - 1e-3).abs() < 1e-8, "{r}");
    }

    /// The sphere lamp's field: 1/d^2 far away, the half-space 2/r^2 on its surface, its
    /// interior by model, and a lamp under `near` the ball mean.
    #[test]
    fn lamp_inverse_square_cases() {
        let r = 0.5;
        assert!((lamp_inverse_square(100.0, r, 0.0, false) * 1e4 - 1.0).abs() < 1e-4);
        assert!((lamp_inverse_square(r, r, 0.0, false) - 2.0 / (r * r)).abs() < 1e-5);
        assert_eq!(lamp_inverse_square(0.3, r, 0.0, false), 0.0);
        assert!((lamp_inverse_square(0.3, r, 0.0, true) - 2.0 / (r * r)).abs() < 1e-5);
        assert_eq!(lamp_inverse_square(2.0, 0.0, 0.0, true), 0.25);
        assert!((lamp_inverse_square(0.3, 0.1, 0.2, false) - ball_mean_inverse_square(0.3, (0.05f32).sqrt())).abs() < 1e-5);
        // Unresolved and lit: the interior's 2/r^2 over the sphere's volume, spread over the ball.
        let b = 0.05f32.sqrt();
        let added = (lamp_inverse_square(0.1, 0.1, 0.2, true) - lamp_inverse_square(0.1, 0.1, 0.2, false)) * b.powi(3);
        assert!((added - 2.0 / 0.01 * 0.001).abs() < 1e-5, "{added}");
        // Exact: 2 (1 - cos(asin(r/d))) / r^2 at d = 2r is (2 - sqrt 3) * 2 / r^2 = 2.1436.
        assert!((lamp_inverse_square(1.0, r, 0.0, false) - 2.0 * (2.0 - 3f32.sqrt()) * 2.0 / 1.0).abs() < 1e-4);
    }
}
