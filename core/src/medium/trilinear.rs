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

/// What a grid answers at an integer lattice point (zero or a clamped value outside it).
/// Closures `Fn(IVec3) -> T` are lattices; the hot grids (density, mip levels) implement it
/// with an always-inlined `at`, since LLVM leaves a closure that holds a whole brick lookup out
/// of line (measured: 20% of a pop render's time in the compositor).
pub trait Lattice<T> {
    fn at(&self, c: IVec3) -> T;
}

impl<T, F: Fn(IVec3) -> T> Lattice<T> for F {
    #[inline(always)]
    fn at(&self, c: IVec3) -> T {
        self(c)
    }
}

/// Coordinates at or beyond this magnitude (and NaN) read zero: `floor` of them does not fit
/// an i32 with room for the `+ 1` of the far corner, and no grid is that large
/// (`GridLimits::max_extent_voxels` is 2^33 voxels, 2^11 per axis for a cube).
pub const MAX_COORD: f32 = (1u32 << 30) as f32;

/// `a (1 - t) + b t`: exact at both ends (a at t = 0, b at t = 1), unlike `a + (b - a) t`.
#[inline(always)]
pub fn lerp<T: Texel>(a: T, b: T, t: f32) -> T {
    a * (1.0 - t) + b * t
}

/// Trilinear interpolation at continuous lattice coordinates `p` (lattice points at integers)
/// of the values `fetch` returns at lattice points; x is interpolated first, then y, then z.
/// `fetch` is only called with points within 1 of `floor(p)`; it must answer every integer
/// point (zero or a clamped value outside the grid). NaN or huge `p` give zero without calling
/// `fetch`. Always inlined, like `Lattice::at` of the hot grids (see `Lattice`).
#[inline(always)]
pub fn trilinear<T: Texel>(p: Vec3, fetch: impl Lattice<T>) -> T {
    // cmplt is false for NaN, so NaN coordinates take this exit too.
    if !p.abs().cmplt(Vec3::splat(MAX_COORD)).all() {
        return T::ZERO;
    }
    let f = p.floor();
    trilinear_cell(f.as_ivec3(), p - f, fetch)
}

/// The interpolation itself, for a caller that picks the cell: the values at `i + {0,1}^3`
/// weighted by the fractions `t` (in [0, 1] for interpolation).
#[inline(always)]
pub fn trilinear_cell<T: Texel>(i: IVec3, t: Vec3, fetch: impl Lattice<T>) -> T {
    // Written out, not through a closure: LLVM may leave a closure out of line (see `Lattice`).
    let c00 = lerp(fetch.at(i), fetch.at(i + IVec3::new(1, 0, 0)), t.x);
    let c10 = lerp(fetch.at(i + IVec3::new(0, 1, 0)), fetch.at(i + IVec3::new(1, 1, 0)), t.x);
    let c01 = lerp(fetch.at(i + IVec3::new(0, 0, 1)), fetch.at(i + IVec3::new(1, 0, 1)), t.x);
    let c11 = lerp(fetch.at(i + IVec3::new(0, 1, 1)), fetch.at(i + IVec3::new(1, 1, 1)), t.x);
    lerp(lerp(c00, c10, t.y), lerp(c01, c11, t.y), t.z)
}

/// Trilinear lookup in a dense x-fastest array of `dims` lattice points at `p`, which the
/// caller has checked or clamped into [0, dims - 1]: the cell is clamped to dims - 2 so that
/// its far corners exist (points on the last lattice plane get the fraction 1), which saves
/// clamping each corner; grids one point thin clamp the corners instead.
#[inline]
pub fn dense_inside<T: Texel>(p: Vec3, dims: IVec3, data: &[T]) -> T {
    if dims.min_element() < 2 {
        return trilinear(p, |c: IVec3| data[clamped_index(c, dims)]);
    }
    let i = p.floor().as_ivec3().clamp(IVec3::ZERO, dims - IVec3::splat(2));
    trilinear_cell(i, p - i.as_vec3(), |c: IVec3| data[(c.x + dims.x * (c.y + dims.y * c.z)) as usize])
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
            let v: f32 = trilinear(p, |c: IVec3| f(c.as_vec3()));
            assert!((v - f(p)).abs() < 1e-5 * (1.0 + f(p).abs()), "{p}: {v} vs {}", f(p));
            let v3: Vec3 = trilinear(p, |c: IVec3| Vec3::splat(f(c.as_vec3())));
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

    /// `dense_inside` (cell clamped to dims - 2) agrees with the corner-clamped lookup on a
    /// 4 x 3 x 2 grid (to 1e-6: fraction 1 versus 0 on the last plane rounds differently),
    /// including points on the far faces, and on grids one point thin.
    #[test]
    fn dense_inside_matches_clamped_lookup() {
        for dims in [IVec3::new(4, 3, 2), IVec3::new(1, 3, 2), IVec3::ONE] {
            let data: Vec<f32> = (0..dims.x * dims.y * dims.z).map(|i| (i * 7 % 5) as f32 + 0.25 * i as f32).collect();
            let hi = (dims - IVec3::ONE).as_vec3();
            let mut rng = crate::rng::Rng::new(9, 9);
            for k in 0..200 {
                let mut p = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * hi;
                if k % 4 == 0 {
                    p.x = hi.x; // on the far face
                }
                let a = dense_inside(p, dims, &data);
                let b: f32 = trilinear(p, |c: IVec3| data[clamped_index(c, dims)]);
                assert!((a - b).abs() < 1e-6 * (1.0 + b.abs()), "{dims} {p}: {a} vs {b}");
            }
        }
    }

    /// NaN, infinite and huge coordinates read zero and never reach `fetch` (which would
    /// index out of bounds or overflow `i + 1`).
    #[test]
    fn nan_and_huge_coordinates_read_zero() {
        for p in [Vec3::NAN, Vec3::new(0.5, f32::NAN, 0.5), Vec3::splat(f32::INFINITY), Vec3::new(3e9, 0.0, 0.0), Vec3::splat(-3e38)] {
            let v: f32 = trilinear(p, |_: IVec3| panic!("fetch called for {p}"));
            assert_eq!(v, 0.0);
        }
        assert!(!inside(Vec3::NAN, Vec3::ZERO, Vec3::ONE));
        assert_eq!(clamped_index(IVec3::new(-5, 9, 2), IVec3::new(4, 4, 4)), 3 * 4 + 2 * 16);
    }
}
