//! The directions of the light propagation maps (Fig. 1): each of the six cube faces owns the
//! directions inside its pyramid (|w_u|, |w_v| <= |w_axis|), sampled as a k x k lattice over
//! the face, a = w_u / |w_axis|, b = w_v / |w_axis| in [-1, 1]^2; n = k^2 propagation
//! directions per face. Every lattice cell is a bin whose solid angle is exact (the solid
//! angle a rectangle on the plane at distance 1 subtends), so the 6 n bins tile the sphere:
//! their solid angles sum to 4 pi to rounding. Storage directions (U) are blocks of
//! s x s lattice cells per face, m = 6 s^2 bins (s = 1: the paper's 6, one per face).

use glam::Vec3;

/// Faces in order +X, -X, +Y, -Y, +Z, -Z: face f marches along axis f / 2, in the
/// positive direction when f is even.
pub const FACES: usize = 6;

/// The (u, v, w) axes of face `f`: w the march axis, u and v the map's axes (cyclic).
#[inline]
pub fn face_axes(f: usize) -> (usize, usize, usize) {
    let w = f / 2;
    ((w + 1) % 3, (w + 2) % 3, w)
}

#[inline]
pub fn face_sign(f: usize) -> f32 {
    if f.is_multiple_of(2) { 1.0 } else { -1.0 }
}

/// Solid angle of the rectangle [a0, a1] x [b0, b1] on the plane at distance 1.
fn rect_solid_angle(a0: f64, a1: f64, b0: f64, b1: f64) -> f64 {
    let f = |a: f64, b: f64| (a * b / (1.0 + a * a + b * b).sqrt()).atan();
    f(a1, b1) - f(a0, b1) - f(a1, b0) + f(a0, b0)
}

/// One propagation direction (bin).
#[derive(Clone, Copy, Debug)]
pub struct Direction {
    pub face: usize,
    /// Lattice offsets: the ray moves `a` cells along u and `b` along v per layer along w.
    pub a: f32,
    pub b: f32,
    /// Unit propagation direction in the world.
    pub w: Vec3,
    /// Solid angle of the bin (sr).
    pub solid_angle: f32,
    /// Storage bin (index into U's m directions).
    pub storage: usize,
}

pub struct Directions {
    /// Lattice side k per face.
    pub k: usize,
    /// Storage blocks per face side.
    pub s: usize,
    /// 6 k^2 directions, face-major: direction i is face i / k^2.
    pub dirs: Vec<Direction>,
    /// Solid angle of each of the m = 6 s^2 storage bins.
    pub storage_solid_angle: Vec<f32>,
    /// `q` x `q` sub-directions per bin (unit vector, solid angle) for the quadratures of the
    /// phase table and the dome's bin integrals.
    pub sub: Vec<Vec<(Vec3, f32)>>,
}

/// Sub-samples per bin side for the bin quadratures. At 4, the phase table's raw row sums
/// (which are 1 exactly) come out within 0.3% for g 0.9 at 25 directions (tests.rs).
const SUB: usize = 4;

/// Sub-samples per bin.
pub const SUBS: usize = SUB * SUB;

fn face_vector(f: usize, a: f64, b: f64) -> Vec3 {
    let (u, v, w) = face_axes(f);
    let mut c = [0.0f64; 3];
    c[u] = a;
    c[v] = b;
    c[w] = face_sign(f) as f64;
    let n = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    Vec3::new((c[0] / n) as f32, (c[1] / n) as f32, (c[2] / n) as f32)
}

/// The storage bins `dirs` read from, sorted, each once, into `out`.
pub fn storage_bins(dirs: &[Direction], out: &mut Vec<usize>) {
    out.clear();
    out.extend(dirs.iter().map(|d| d.storage));
    out.sort_unstable();
    out.dedup();
}

impl Directions {
    pub fn new(k: usize, s: usize) -> Self {
        let k = k.max(1);
        let s = s.clamp(1, k);
        let mut dirs = Vec::with_capacity(FACES * k * k);
        let mut sub = Vec::with_capacity(FACES * k * k);
        let mut storage_solid_angle = vec![0.0f32; FACES * s * s];
        let edge = |i: usize, n: usize| -1.0 + 2.0 * i as f64 / n as f64;
        for f in 0..FACES {
            for ib in 0..k {
                for ia in 0..k {
                    let (a0, a1, b0, b1) = (edge(ia, k), edge(ia + 1, k), edge(ib, k), edge(ib + 1, k));
                    let (a, b) = (0.5 * (a0 + a1), 0.5 * (b0 + b1));
                    let omega = rect_solid_angle(a0, a1, b0, b1);
                    // Block of the lattice cell: proportional, so that s need not divide k.
                    let storage = f * s * s + (ib * s / k) * s + ia * s / k;
                    storage_solid_angle[storage] += omega as f32;
                    dirs.push(Direction { face: f, a: a as f32, b: b as f32, w: face_vector(f, a, b), solid_angle: omega as f32, storage });
                    let mut subs = Vec::with_capacity(SUB * SUB);
                    for jb in 0..SUB {
                        for ja in 0..SUB {
                            let (sa0, sa1) = (a0 + (a1 - a0) * ja as f64 / SUB as f64, a0 + (a1 - a0) * (ja + 1) as f64 / SUB as f64);
                            let (sb0, sb1) = (b0 + (b1 - b0) * jb as f64 / SUB as f64, b0 + (b1 - b0) * (jb + 1) as f64 / SUB as f64);
                            let w = face_vector(f, 0.5 * (sa0 + sa1), 0.5 * (sb0 + sb1));
                            subs.push((w, rect_solid_angle(sa0, sa1, sb0, sb1) as f32));
                        }
                    }
                    sub.push(subs);
                }
            }
        }
        Directions { k, s, dirs, storage_solid_angle, sub }
    }

    /// The most storage bins the directions of one face read from (what a sweep gathers a
    /// cell: `propagate::Layers`).
    pub fn bins_per_face(&self) -> usize {
        let mut bins = Vec::new();
        (0..FACES)
            .map(|f| {
                storage_bins(&self.dirs[f * self.per_face()..(f + 1) * self.per_face()], &mut bins);
                bins.len()
            })
            .max()
            .unwrap_or(0)
    }

    pub fn per_face(&self) -> usize {
        self.k * self.k
    }

    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }

    pub fn storage_len(&self) -> usize {
        self.storage_solid_angle.len()
    }

    /// The bin containing unit direction `w`.
    pub fn bin_of(&self, w: Vec3) -> usize {
        let (f, u, v) = self.face_coordinates(w, self.k);
        f * self.per_face() + v * self.k + u
    }

    /// The sub-sample of its bin that unit `w` falls in, as `bin x SUBS + sub` (`sub` indexes
    /// `self.sub[bin]`): the rows of the table towards the viewer (phase_table.rs).
    pub fn view_index(&self, w: Vec3) -> usize {
        let (f, u, v) = self.face_coordinates(w, self.k * SUB);
        let bin = f * self.per_face() + (v / SUB) * self.k + u / SUB;
        bin * SUBS + (v % SUB) * SUB + u % SUB
    }

    /// The face of unit `w` and its cell (u, v) on an n x n lattice over the face.
    fn face_coordinates(&self, w: Vec3, n: usize) -> (usize, usize, usize) {
        let abs = w.abs();
        let axis = if abs.x >= abs.y && abs.x >= abs.z { 0 } else if abs.y >= abs.z { 1 } else { 2 };
        let c = w.to_array();
        let f = 2 * axis + usize::from(c[axis] < 0.0);
        let (u, v, _) = face_axes(f);
        let inv = 1.0 / abs.max_element().max(1e-30);
        let cell = |x: f32| (((x * inv + 1.0) * 0.5 * n as f32).floor().max(0.0) as usize).min(n - 1);
        (f, cell(c[u]), cell(c[v]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bins tile the sphere: solid angles sum to 4 pi (to f32 rounding), each bin's
    /// sub-samples sum to the bin, and every direction falls in its own bin.
    #[test]
    fn bins_tile_the_sphere() {
        for (k, s) in [(1, 1), (3, 1), (5, 2), (8, 3)] {
            let d = Directions::new(k, s);
            let total: f64 = d.dirs.iter().map(|x| x.solid_angle as f64).sum();
            assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-5, "k {k}: {total}");
            let storage: f64 = d.storage_solid_angle.iter().map(|&x| x as f64).sum();
            assert!((storage - total).abs() < 1e-5);
            for (i, dir) in d.dirs.iter().enumerate() {
                let sub: f32 = d.sub[i].iter().map(|x| x.1).sum();
                assert!((sub - dir.solid_angle).abs() < 1e-5 * dir.solid_angle.max(1.0), "bin {i}");
                assert_eq!(d.bin_of(dir.w), i, "k {k} direction {i} {:?}", dir.w);
                assert!(dir.a.abs() < 1.0 && dir.b.abs() < 1.0);
            }
        }
    }

    /// Every sub-sample's direction has its own view index (its bin's, then its place among
    /// the bin's sub-samples), and a view index's bin is the direction's bin.
    #[test]
    fn view_index_finds_the_sub_sample() {
        for k in [2, 5, 6] {
            let d = Directions::new(k, 1);
            for (i, subs) in d.sub.iter().enumerate() {
                for (s, &(w, _)) in subs.iter().enumerate() {
                    assert_eq!(d.view_index(w), i * SUBS + s, "k {k} bin {i} sub {s}");
                    assert_eq!(d.view_index(w) / SUBS, d.bin_of(w));
                }
            }
        }
    }
}
