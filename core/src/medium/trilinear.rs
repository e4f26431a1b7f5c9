//! The one trilinear lookup of every grid (density, emission, POP's mip levels and light grids,
//! the scattering grid, the radial grids' octahedral shells): a grid supplies only how to fetch
//! the value at an integer lattice point, and decides there what lies outside it (zero, or the
//! edge value). The WGSL kernels use the same formula (shaders/src/wgsl/trilinear.wgsl), so CPU
//! and GPU round alike.

use glam::{IVec3, Vec3};
use std::ops::{Add, Mul};

/// A value that can be interpolated: f32, Vec3, ...
pub trait Texel: Copy + Add<Output = Self> + Mul<f32, Output = Self> {
    const ZERO: Self;
}

impl Texel for f32 {
    const ZERO: f32 = 0.0;
}

impl Texel for Vec3 {
    const ZERO: Vec3 = Vec3::ZERO;
}

/// Coordinates at or beyond this magnitude (and NaN) read zero: `floor` of them does not fit
/// an i32 with room for the `+ 1` of the far corner, and no grid is that large
/// (`GridLimits::max_extent_voxels` is 2^33 voxels, 2^11 per axis for a cube).
pub const MAX_COORD: f32 = (1u32 << 30) as f32;

/// `a (1 - t) + b t`: exact at both ends (a at t = 0, b at t = 1), unlike `a + (b - a) t`.
#[inline]
pub fn lerp<T: Texel>(a: T, b: T, t: f32) -> T {
    a * (1.0 - t) + b * t
}

/// Trilinear interpolation at continuous lattice coordinates `p` (lattice points at integers)
/// of the values `fetch` returns at lattice points; x is interpolated first, then y, then z.
/// `fetch` is only called with points within 1 of `floor(p)`; it must answer every integer
/// point (zero or a clamped value outside the grid). NaN or huge `p` give zero without calling
/// `fetch`.
#[inline]
pub fn trilinear<T: Texel>(p: Vec3, fetch: impl Fn(IVec3) -> T) -> T {
    // cmplt is false for NaN, so NaN coordinates take this exit too.
    if !p.abs().cmplt(Vec3::splat(MAX_COORD)).all() {
        return T::ZERO;
    }
    let f = p.floor();
    let i = f.as_ivec3();
    let t = p - f;
    let v = |dx: i32, dy: i32, dz: i32| fetch(i + IVec3::new(dx, dy, dz));
    let c00 = lerp(v(0, 0, 0), v(1, 0, 0), t.x);
    let c10 = lerp(v(0, 1, 0), v(1, 1, 0), t.x);
    let c01 = lerp(v(0, 0, 1), v(1, 0, 1), t.x);
    let c11 = lerp(v(0, 1, 1), v(1, 1, 1), t.x);
    lerp(lerp(c00, c10, t.y), lerp(c01, c11, t.y), t.z)
}

/// Index of lattice point `c` in a dense x-fastest array of `dims` points, `c` clamped into
/// the array (the edge value continues outside). `dims` must be at least 1 on every axis.
#[inline]
pub fn clamped_index(c: IVec3, dims: IVec3) -> usize {
    let c = c.clamp(IVec3::ZERO, dims - IVec3::ONE);
    (c.x + dims.x * (c.y + dims.y * c.z)) as usize
}

/// True when `p` lies in the box [lo, hi] (false for NaN).
#[inline]
pub fn inside(p: Vec3, lo: Vec3, hi: Vec3) -> bool {
    p.cmpge(lo).all() && p.cmple(hi).all()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A trilinear function a + b.p + c xy + ... is reproduced exactly by trilinear
    /// interpolation of its lattice values; checked for x + 2y + 4z + xyz at random points to
    /// 1e-5 (float rounding of values up to ~100).
    #[test]
    fn reproduces_a_trilinear_function() {
        let f = |p: Vec3| p.x + 2.0 * p.y + 4.0 * p.z + p.x * p.y * p.z;
        let mut rng = crate::rng::Rng::new(3, 4);
        for _ in 0..1000 {
            let p = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 8.0 - 2.0;
            let v: f32 = trilinear(p, |c| f(c.as_vec3()));
            assert!((v - f(p)).abs() < 1e-5 * (1.0 + f(p).abs()), "{p}: {v} vs {}", f(p));
            let v3: Vec3 = trilinear(p, |c| Vec3::splat(f(c.as_vec3())));
            assert_eq!(v3, Vec3::splat(v), "Vec3 and f32 lookups must round alike");
        }
    }

    /// At lattice points the lookup returns the stored value bit for bit (lerp is exact at t=0).
    #[test]
    fn exact_at_lattice_points() {
        let f = |c: IVec3| (c.x * 7 + c.y * 3 - c.z) as f32 * 0.1;
        for c in [IVec3::ZERO, IVec3::new(3, -2, 5), IVec3::new(-7, 1, 0)] {
            assert_eq!(trilinear(c.as_vec3(), f), f(c));
        }
    }

    /// NaN, infinite and huge coordinates read zero and never reach `fetch` (which would
    /// index out of bounds or overflow `i + 1`).
    #[test]
    fn nan_and_huge_coordinates_read_zero() {
        for p in [Vec3::NAN, Vec3::new(0.5, f32::NAN, 0.5), Vec3::splat(f32::INFINITY), Vec3::new(3e9, 0.0, 0.0), Vec3::splat(-3e38)] {
            let v: f32 = trilinear(p, |_| panic!("fetch called for {p}"));
            assert_eq!(v, 0.0);
        }
        assert!(!inside(Vec3::NAN, Vec3::ZERO, Vec3::ONE));
        assert_eq!(clamped_index(IVec3::new(-5, 9, 2), IVec3::new(4, 4, 4)), 3 * 4 + 2 * 16);
    }
}
