//! The angular coordinates of a radial grid (paper 01 Sec. 6): the octahedral parametrisation
//! of the sphere of directions as a square of n x n cells, each with four natural neighbours.
//!
//! Departure from the paper's reference [30] (the plain octahedral map): the *equal-area*
//! octahedral map (Clarberg 2008, as pbrt-v4's EqualAreaSquareToSphere). Same square, same
//! folding at the border, but every cell has the same solid angle 4 pi / n^2, so an isotropic
//! source puts the same power in every column and a cell's volume depends on its shell only.
//!
//! The square's border is folded: the edge u = 0 at v and at 1 - v is the same direction, and
//! likewise for the other three edges. A neighbour across an edge is therefore the mirrored
//! cell of the same row (pbrt's WrapEqualAreaSquare); the relation is symmetric, so energy
//! sent to neighbours is conserved.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};

/// Direction for a point of the unit square (equal-area octahedral map).
pub fn square_to_sphere(p: Vec2) -> Vec3 {
    let (u, v) = (2.0 * p.x - 1.0, 2.0 * p.y - 1.0);
    let (up, vp) = (u.abs(), v.abs());
    // Signed distance from the diagonal |u| + |v| = 1 (the equator).
    let signed = 1.0 - (up + vp);
    let r = 1.0 - signed.abs();
    let phi = if r == 0.0 { 1.0 } else { (vp - up) / r + 1.0 } * FRAC_PI_4;
    let z = (1.0 - r * r).copysign(signed);
    let s = r * (2.0 - r * r).max(0.0).sqrt();
    Vec3::new(phi.cos().copysign(u) * s, phi.sin().copysign(v) * s, z).normalize_or(Vec3::Z)
}

/// Point of the unit square for a unit direction; inverse of `square_to_sphere`.
pub fn sphere_to_square(d: Vec3) -> Vec2 {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    let r = (1.0 - z).max(0.0).sqrt();
    let (a, b) = (x.max(y), x.min(y));
    let b = if a == 0.0 { 0.0 } else { b / a };
    let mut phi = b.atan() / FRAC_PI_2;
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if d.z < 0.0 {
        std::mem::swap(&mut u, &mut v);
        u = 1.0 - u;
        v = 1.0 - v;
    }
    Vec2::new(0.5 * (u.copysign(d.x) + 1.0), 0.5 * (v.copysign(d.y) + 1.0))
}

/// The cell (i, j) that integer coordinates outside [0, n) stand for, one cell across the
/// folded border (and the cell itself inside).
#[inline]
pub fn wrap(mut i: i32, mut j: i32, n: i32) -> (u32, u32) {
    if i < 0 {
        i = -1 - i;
        j = n - 1 - j;
    } else if i >= n {
        i = 2 * n - 1 - i;
        j = n - 1 - j;
    }
    if j < 0 {
        j = -1 - j;
        i = n - 1 - i;
    } else if j >= n {
        j = 2 * n - 1 - j;
        i = n - 1 - i;
    }
    (i.clamp(0, n - 1) as u32, j.clamp(0, n - 1) as u32)
}

/// Per column (i + n j): its four angular neighbours (-u, +u, -v, +v) and the column of the
/// opposite direction, through which light crossing the centre continues.
pub struct Columns {
    pub n: u32,
    pub directions: Vec<Vec3>,
    pub neighbours: Vec<[u32; 4]>,
    pub antipode: Vec<u32>,
}

impl Columns {
    /// `n` must be even (the folding then maps cell centres onto cell centres).
    pub fn new(n: u32) -> Self {
        let ni = n as i32;
        let mut directions = Vec::with_capacity((n * n) as usize);
        let mut neighbours = Vec::with_capacity((n * n) as usize);
        let mut antipode = Vec::with_capacity((n * n) as usize);
        let col = |(i, j): (u32, u32)| i + n * j;
        for j in 0..ni {
            for i in 0..ni {
                let d = square_to_sphere(Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32));
                directions.push(d);
                neighbours.push([col(wrap(i - 1, j, ni)), col(wrap(i + 1, j, ni)), col(wrap(i, j - 1, ni)), col(wrap(i, j + 1, ni))]);
                antipode.push(col(cell_of(-d, n)));
            }
        }
        Columns { n, directions, neighbours, antipode }
    }
}

/// The cell holding direction `d`.
pub fn cell_of(d: Vec3, n: u32) -> (u32, u32) {
    let p = sphere_to_square(d) * n as f32;
    ((p.x as i32).clamp(0, n as i32 - 1) as u32, (p.y as i32).clamp(0, n as i32 - 1) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_round_trips_and_is_equal_area() {
        let n = 16u32;
        for j in 0..64 {
            for i in 0..64 {
                let p = Vec2::new((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 64.0);
                let d = square_to_sphere(p);
                assert!((d.length() - 1.0).abs() < 1e-5);
                let q = sphere_to_square(d);
                assert!((q - p).abs().max_element() < 1e-4, "{p} -> {d} -> {q}");
            }
        }
        // Equal area: uniform directions land uniformly in the cells (chi-square-like check).
        let mut counts = vec![0u32; (n * n) as usize];
        let k = 512;
        for a in 0..k {
            for b in 0..k {
                let d = crate::sampling::uniform_sphere([(a as f32 + 0.5) / k as f32, (b as f32 + 0.5) / k as f32]);
                let (i, j) = cell_of(d, n);
                counts[(i + n * j) as usize] += 1;
            }
        }
        let mean = (k * k) as f32 / (n * n) as f32;
        for c in counts {
            assert!((c as f32 / mean - 1.0).abs() < 0.08, "{c} vs {mean}");
        }
    }

    #[test]
    fn neighbours_are_symmetric_adjacent_and_antipodes_involutive() {
        let n = 8u32;
        let cols = Columns::new(n);
        let cell_angle = (4.0 * std::f32::consts::PI / (n * n) as f32).sqrt();
        for c in 0..(n * n) as usize {
            for &nb in &cols.neighbours[c] {
                let back = cols.neighbours[nb as usize].iter().filter(|&&x| x as usize == c).count();
                let fwd = cols.neighbours[c].iter().filter(|&&x| x == nb).count();
                assert_eq!(back, fwd, "column {c} and {nb}");
                // Neighbours are near: within about two cell widths.
                let ang = cols.directions[c].dot(cols.directions[nb as usize]).clamp(-1.0, 1.0).acos();
                assert!(ang < 2.5 * cell_angle, "column {c} -> {nb}: {ang} rad");
            }
            let a = cols.antipode[c] as usize;
            assert_eq!(cols.antipode[a] as usize, c);
            assert!(cols.directions[a].dot(cols.directions[c]) < -0.999);
        }
    }
}
