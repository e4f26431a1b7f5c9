//! The cost guard of the shadow-ray sums over point emitters (the single-scattering grid,
//! network's direct light, lpm's first scattering): each emitter costs a shadow ray at every
//! grid point, so thousands of point lights (or area lights cut into VPLs) took many times a
//! solver's usual time (BENCHMARKS.md, "Cost guard on extreme scenes"). Past `TREE_ABOVE`
//! emitters they are put in a binary tree by position (one per angular profile, so a merged
//! node keeps its members' direction dependence exactly), and a point sums a node as one
//! emitter (its members' summed intensity at their power-weighted centre) where the node is
//! small as seen from it: radius < `OPENING` x distance, the lightcuts-style opening rule. The
//! 1/d^2 of the members then differs from the centre's by O(OPENING^2) (the first order
//! cancels at the centroid), and their shadow rays converge on the point; nearer nodes open
//! down to the emitters themselves, which are summed exactly.

use glam::Vec3;

use super::emitters::{Extent, PointEmitter, Profile};

/// Emitters summed one by one up to this many (the tree's answer differs from the exact sum,
/// slightly; up to four area lights of 8 x 8 VPLs stay exact).
pub const TREE_ABOVE: usize = 256;

/// A node stands for its emitters where its radius is below this fraction of its distance:
/// its members' directions are within 15 degrees of the centre's, and their 1/d^2's mean is
/// the centre's within 25% before `inverse_square_factor`'s second-order correction. Measured
/// on 600 point and spot lights above a plume (solvers/many_lights_tests.rs), the
/// single-scattering grid is within 0.3% of the exact sum in total and 0.9% in L1, at a
/// fraction of the shadow rays.
pub const OPENING: f32 = 0.25;

struct Node {
    /// The emitter a point sums for the whole node (a leaf: the emitter itself).
    merged: PointEmitter,
    /// Radius of the ball about `merged.position` holding the members (with their own radii).
    radius: f32,
    /// Children (None: a leaf).
    children: Option<(u32, u32)>,
    /// The members' power-weighted covariance of position about the centre (xx, yy, zz, xy,
    /// xz, yz), for `inverse_square_factor`.
    cov: [f32; 6],
}

/// The members' mean of 1/d^2 over the centre's, to second order in their spread: 1/d^2 is
/// convex, so the centre alone is always low (-1% in total on `many_lights_single_scattering`
/// without this). The Hessian of |p - x|^-2 averaged over the members' covariance S is
/// (4 u.S.u - tr S) / d^4, u the unit direction from `x` to the centre at distance d.
fn inverse_square_factor(cov: &[f32; 6], to: Vec3) -> f32 {
    let d2 = to.length_squared();
    if d2 <= 0.0 {
        return 1.0;
    }
    let u = to / d2.sqrt();
    let [xx, yy, zz, xy, xz, yz] = *cov;
    let usu = u.x * u.x * xx + u.y * u.y * yy + u.z * u.z * zz + 2.0 * (u.x * u.y * xy + u.x * u.z * xz + u.y * u.z * yz);
    // Within the opening rule the term is at most 4 OPENING^2 = 0.25: the clamp only guards
    // rounding.
    (1.0 + (4.0 * usu - (xx + yy + zz)) / d2).clamp(0.5, 2.0)
}

/// Point emitters as a sum that is cheap however many there are (see the module docs).
pub struct EmitterTree {
    /// The emitters summed one by one, in their order (flat: no tree).
    flat: Vec<PointEmitter>,
    nodes: Vec<Node>,
    roots: Vec<u32>,
    len: usize,
}

impl EmitterTree {
    /// `emitters` as a tree when there are more than `TREE_ABOVE`, else summed one by one.
    pub fn new(emitters: Vec<PointEmitter>) -> Self {
        Self::with_threshold(emitters, TREE_ABOVE)
    }

    /// `new` with the tree from `above` emitters (tests: `usize::MAX` for the exact sum).
    pub fn with_threshold(emitters: Vec<PointEmitter>, above: usize) -> Self {
        let len = emitters.len();
        if len <= above {
            return EmitterTree { flat: emitters, nodes: Vec::new(), roots: Vec::new(), len };
        }
        // One tree per profile: a merged node's intensity is then exact in every direction.
        let mut groups: Vec<(Profile, Vec<PointEmitter>)> = Vec::new();
        for e in emitters {
            match groups.iter_mut().find(|(p, _)| *p == e.profile) {
                Some((_, g)) => g.push(e),
                None => groups.push((e.profile, vec![e])),
            }
        }
        let mut tree = EmitterTree { flat: Vec::new(), nodes: Vec::with_capacity(2 * len), roots: Vec::new(), len };
        for (_, mut g) in groups {
            let root = tree.build(&mut g);
            tree.roots.push(root);
        }
        tree
    }

    /// How many emitters this stands for.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether points sum merged nodes (more than `TREE_ABOVE` emitters).
    pub fn merges(&self) -> bool {
        !self.roots.is_empty()
    }

    fn build(&mut self, members: &mut [PointEmitter]) -> u32 {
        if members.len() == 1 {
            self.nodes.push(Node { merged: members[0], radius: members[0].radius, children: None, cov: [0.0; 6] });
            return self.nodes.len() as u32 - 1;
        }
        let weight = |e: &PointEmitter| e.intensity.element_sum().max(1e-30);
        let total: f32 = members.iter().map(weight).sum();
        let centre = members.iter().map(|e| e.position * weight(e)).sum::<Vec3>() / total;
        let radius = members.iter().map(|e| e.position.distance(centre) + e.radius).fold(0.0f32, f32::max);
        let intensity = members.iter().map(|e| e.intensity).sum::<Vec3>();
        let mut cov = [0.0f32; 6];
        for e in members.iter() {
            let (v, w) = (e.position - centre, weight(e) / total);
            for (c, p) in cov.iter_mut().zip([v.x * v.x, v.y * v.y, v.z * v.z, v.x * v.y, v.x * v.z, v.y * v.z]) {
                *c += w * p;
            }
        }
        let (lo, hi) = members.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(l, h), e| (l.min(e.position), h.max(e.position)));
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z { 0 } else if ext.y >= ext.z { 1 } else { 2 };
        let mid = members.len() / 2;
        members.select_nth_unstable_by(mid, |a, b| a.position[axis].total_cmp(&b.position[axis]));
        let (a, b) = members.split_at_mut(mid);
        let left = self.build(a);
        let right = self.build(b);
        let merged = PointEmitter { position: centre, intensity, radius: 0.0, extent: Extent::Ball, profile: members[0].profile };
        self.nodes.push(Node { merged, radius, children: Some((left, right)), cov });
        self.nodes.len() as u32 - 1
    }

    /// Calls `f` with the emitters whose sum stands for all of them at `x`: every emitter
    /// (in order) when flat, else the tree's cut for `x`.
    #[inline]
    pub fn visit(&self, x: Vec3, mut f: impl FnMut(&PointEmitter)) {
        if self.roots.is_empty() {
            self.flat.iter().for_each(f);
            return;
        }
        // Depth is at most log2(len) + 1 per tree (median splits): 64 entries suffice.
        let mut stack = [0u32; 64];
        for &root in &self.roots {
            let mut top = 1;
            stack[0] = root;
            while top > 0 {
                top -= 1;
                let node = &self.nodes[stack[top] as usize];
                match node.children {
                    Some((l, r)) if node.radius >= OPENING * node.merged.position.distance(x) => {
                        stack[top] = l;
                        stack[top + 1] = r;
                        top += 2;
                    }
                    Some(_) => {
                        let k = inverse_square_factor(&node.cov, node.merged.position - x);
                        f(&PointEmitter { intensity: node.merged.intensity * k, ..node.merged })
                    }
                    None => f(&node.merged),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::light::SphereInterior;

    fn point(p: Vec3, i: f32, profile: Profile) -> PointEmitter {
        PointEmitter { position: p, intensity: Vec3::splat(i), radius: 0.0, extent: Extent::Sphere(SphereInterior::Dark), profile }
    }

    /// The field sum_e I_e(w) / d^2 through the tree against the exact sum, at points near and
    /// far from 2000 lights on a plane (two profiles): within 2% everywhere (the opening rule's
    /// O(OPENING^2) = 6% per node, cancelling to first order), with far fewer terms far away.
    #[test]
    fn tree_field_matches_exact_sum() {
        let cone = Profile::Cone { axis: -Vec3::Z, cos_outer: 0.5, cos_inner: 0.8 };
        let lights: Vec<PointEmitter> = (0..2000)
            .map(|k| {
                let (u, v) = ((k * 7919 % 2000) as f32 / 2000.0, (k * 104729 % 1999) as f32 / 1999.0);
                point(Vec3::new(4.0 * u - 2.0, 4.0 * v - 2.0, 2.0), 1.0 + (k % 5) as f32, if k % 2 == 0 { Profile::Isotropic } else { cone })
            })
            .collect();
        let exact = EmitterTree::with_threshold(lights.clone(), usize::MAX);
        let tree = EmitterTree::new(lights);
        assert!(tree.merges() && !exact.merges() && tree.len() == 2000);
        let field = |t: &EmitterTree, x: Vec3| {
            let (mut sum, mut terms) = (0.0f32, 0);
            t.visit(x, |e| {
                let to = e.position - x;
                sum += e.intensity_towards(-to.normalize()).x / to.length_squared();
                terms += 1;
            });
            (sum, terms)
        };
        for x in [Vec3::new(0.0, 0.0, 1.5), Vec3::new(1.0, -0.5, 0.5), Vec3::new(0.0, 0.0, -1.0), Vec3::new(3.0, 3.0, 0.0), Vec3::new(0.0, 0.0, -10.0)] {
            let ((a, n_exact), (b, n_tree)) = (field(&exact, x), field(&tree, x));
            assert_eq!(n_exact, 2000);
            assert!((b / a - 1.0).abs() < 0.02, "at {x}: tree {b} exact {a} ({n_tree} terms)");
            if x.z < 0.0 {
                assert!(n_tree < 400, "at {x}: {n_tree} terms");
            }
        }
    }
}
