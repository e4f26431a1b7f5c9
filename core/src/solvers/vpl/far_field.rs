//! `cluster_distance` (settings.rs): the VPLs far from a gather point taken as clusters instead
//! of one by one, found through a pyramid over the gather grid.
//!
//! Why: the gather connects every point to every VPL, so its cost is points x VPLs and the
//! walks that bring the noise down cost their VPLs' connections at all ~4000 points (default
//! scene: 65536 walks, 1.4 s of a 2.2 s render). The far VPLs' light changes slowly across
//! space, so a cluster of them at a distance of a few of its sizes acts as one VPL; only the
//! near ones, which carry most of J and vary fastest, need connecting one by one.
//!
//! The tree: the gather grid's cells (one per point, the box of half a spacing around it), in
//! base cells of a power of two of them (so that the base level has at most `MAX_BASE` cells a
//! side), and a pyramid of 2 x 2 x 2 merges above them. Each node keeps its VPLs' power, their
//! power-weighted centroid, mean incident direction and spread. A point connects to a base
//! cell nearer than `cluster_distance` of its sides one VPL at a time, to a farther one once;
//! the levels above only skip what is empty (`MAX_CLUSTER_LEVEL`: why not larger clusters).
//!
//! A cluster as one connection (gather.rs `connect_clusters`): from its centroid; its VPLs'
//! HG lobes as a share |m| of whole lobes about their mean incident direction m and the rest
//! isotropic: the same energy and mean cosine as their sum, exact where they all arrive along
//! one direction (the first collisions of a sun's walks) and right where the rest are spread
//! evenly (measured better than one lobe of g |m|: `MAX_CLUSTER_LEVEL`). 1/d^2 with its mean
//! over the cluster's spread to second order: the Laplacian of 1/|y|^2 is 2/|y|^4, so the mean
//! over VPLs spread with mean squared distance s^2 about the centroid is 1/d^2 (1 + s^2 /
//! (3 d^2)) (isotropic spread); both lobes are widened by that spread's angle (g times 1 - s^2
//! / (3 d^2)). The transmittance is the centroid's (from the point's depth map, as every
//! connection beyond a cell already is), with its mean over the spread along the line to
//! second order, sigma the extinction at the centroid and v = s^2 / 3 the radial variance:
//! e^-tau is convex (x (1 + sigma^2 v / 2)) and the nearer VPLs of a cluster are both less
//! attenuated and closer (x (1 + 2 sigma v / d)); without it the clusters' J_iso on cube g 0.7
//! (4096 walks, distance 2) was 0.6% low.

use glam::{Affine3A, UVec3, Vec3};

use super::walks::Vpl;
use crate::error::Result;
use crate::medium::Medium;

/// Largest side of the base level in base cells: base cells are merged gather cells where the
/// gather is finer (bounds the tree's memory at ~64^3 x 8/7 nodes).
pub const MAX_BASE: u32 = 64;

/// The highest level of the tree whose nodes are taken as clusters: the base cells alone.
/// Why: a larger node's VPLs mix first-order ones, all arriving along the light, with
/// scattered ones, whose directions one lobe model cannot hold (the lobe models measured:
/// docs/solvers/vpl.md).
pub const MAX_CLUSTER_LEVEL: u32 = 0;

/// A node of the tree: what its VPLs are, seen from afar.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cluster {
    /// Sum of the VPLs' powers (W, RGB).
    pub power: Vec3,
    /// Power-weighted centroid (weights: the powers' channel sums).
    pub centroid: Vec3,
    /// Power-weighted mean of the VPLs' incident directions (|m| <= 1).
    pub mean_incident: Vec3,
    /// Power-weighted mean squared distance of the VPLs from the centroid (world units^2).
    pub spread: f32,
    /// The medium's extinction at the centroid (per channel; set by `FarField::new`).
    pub extinction: Vec3,
}

/// Sums over a node's VPLs, in f64 while the tree is built (the spread is a difference of two
/// of them).
#[derive(Clone, Copy, Default)]
struct Sums {
    weight: f64,
    position: [f64; 3],
    incident: [f64; 3],
    square: f64,
    power: [f64; 3],
}

impl Sums {
    fn add_vpl(&mut self, v: &Vpl) {
        let w = v.power.element_sum() as f64;
        self.weight += w;
        for a in 0..3 {
            self.position[a] += w * v.position[a] as f64;
            self.incident[a] += w * v.incident[a] as f64;
            self.power[a] += v.power[a] as f64;
        }
        self.square += w * v.position.length_squared() as f64;
    }

    fn add(&mut self, o: &Sums) {
        self.weight += o.weight;
        self.square += o.square;
        for a in 0..3 {
            self.position[a] += o.position[a];
            self.incident[a] += o.incident[a];
            self.power[a] += o.power[a];
        }
    }

    fn cluster(&self) -> Cluster {
        if self.weight <= 0.0 {
            return Cluster::default();
        }
        let c = [self.position[0] / self.weight, self.position[1] / self.weight, self.position[2] / self.weight];
        let spread = (self.square / self.weight - (c[0] * c[0] + c[1] * c[1] + c[2] * c[2])).max(0.0);
        let f = |v: [f64; 3], s: f64| Vec3::new((v[0] * s) as f32, (v[1] * s) as f32, (v[2] * s) as f32);
        Cluster { power: f(self.power, 1.0), centroid: f(c, 1.0), mean_incident: f(self.incident, 1.0 / self.weight), spread: spread as f32, extinction: Vec3::ZERO }
    }
}

struct Level {
    dims: UVec3,
    nodes: Vec<Cluster>,
}

/// The tree over one list of VPLs (one interleaved subset's).
pub struct FarField {
    /// The VPLs, sorted by base cell.
    vpls: Vec<Vpl>,
    /// Base cell c's VPLs are `vpls[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    /// levels[0]: the base cells; each next one merges 2 x 2 x 2, up to a single node.
    levels: Vec<Level>,
    /// Gather cells per base cell side (a power of two).
    base: u32,
    world_to_index: Affine3A,
    /// Shortest and longest world length of one gather spacing (the criterion is measured in
    /// world units: nearest distance against longest side).
    min_spacing: f32,
    max_spacing: f32,
    /// `cluster_distance`.
    opening: f32,
}

fn cell_index(dims: UVec3, c: UVec3) -> usize {
    (c.x + dims.x * (c.y + dims.y * c.z)) as usize
}

impl FarField {
    /// The tree of `vpls` over a gather grid of `dims` points placed by `index_to_world`; a
    /// node is opened where it is nearer than `opening` of its sides.
    pub fn new(vpls: &[Vpl], dims: [u32; 3], index_to_world: &Affine3A, opening: f32, medium: Option<&Medium>) -> Result<Self> {
        let gather = UVec3::from_array(dims).max(UVec3::ONE);
        let mut base = 1u32;
        while gather.max_element().div_ceil(base) > MAX_BASE {
            base *= 2;
        }
        let base_dims = (gather + UVec3::splat(base - 1)) / base;
        let cells = (base_dims.x * base_dims.y * base_dims.z) as u64;
        crate::budget::check_elements::<[Cluster; 2]>("vpl far-field tree", cells)?;
        crate::budget::check_elements::<Vpl>("vpl far-field tree's VPLs", vpls.len() as u64)?;
        let world_to_index = index_to_world.inverse();
        let base_cell = |p: Vec3| {
            let q = world_to_index.transform_point3(p).round();
            let i = q.clamp(Vec3::ZERO, (gather - UVec3::ONE).as_vec3()).as_uvec3();
            cell_index(base_dims, (i / base).min(base_dims - UVec3::ONE))
        };
        // Counting sort by base cell.
        let keys: Vec<u32> = vpls.iter().map(|v| base_cell(v.position) as u32).collect();
        let mut start = vec![0u32; cells as usize + 1];
        for &k in &keys {
            start[k as usize + 1] += 1;
        }
        for c in 0..cells as usize {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut sorted = vec![Vpl { position: Vec3::ZERO, incident: Vec3::Z, power: Vec3::ZERO }; vpls.len()];
        for (v, &k) in vpls.iter().zip(&keys) {
            sorted[fill[k as usize] as usize] = *v;
            fill[k as usize] += 1;
        }
        // The base level's sums, then each level's from the one below.
        let mut sums: Vec<Sums> = (0..cells as usize)
            .map(|c| {
                let mut s = Sums::default();
                sorted[start[c] as usize..start[c + 1] as usize].iter().for_each(|v| s.add_vpl(v));
                s
            })
            .collect();
        let mut dims_l = base_dims;
        // The extinction only where nodes are connected as clusters (`MAX_CLUSTER_LEVEL`).
        let cluster = |s: &Sums, level: u32| {
            let mut c = s.cluster();
            if let Some(m) = medium.filter(|_| level <= MAX_CLUSTER_LEVEL) {
                c.extinction = m.sigma_t(m.density_world(c.centroid).max(0.0));
            }
            c
        };
        let mut levels = vec![Level { dims: dims_l, nodes: sums.iter().map(|s| cluster(s, 0)).collect() }];
        while dims_l.max_element() > 1 {
            let up = (dims_l + UVec3::ONE) / 2;
            let mut next = vec![Sums::default(); (up.x * up.y * up.z) as usize];
            for z in 0..dims_l.z {
                for y in 0..dims_l.y {
                    for x in 0..dims_l.x {
                        let c = UVec3::new(x, y, z);
                        next[cell_index(up, c / 2)].add(&sums[cell_index(dims_l, c)]);
                    }
                }
            }
            let level = levels.len() as u32;
            levels.push(Level { dims: up, nodes: next.iter().map(|s| cluster(s, level)).collect() });
            sums = next;
            dims_l = up;
        }
        let m = index_to_world.matrix3;
        let lengths = Vec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
        Ok(FarField { vpls: sorted, start, levels, base, world_to_index, min_spacing: lengths.min_element(), max_spacing: lengths.max_element(), opening })
    }

    /// Every VPL once, seen from world point `x`: the near ones' slices to `near`, the far
    /// clusters to `far`. `stack` is scratch space, reused from point to point.
    pub fn visit(&self, x: Vec3, stack: &mut Vec<(u32, UVec3)>, near: impl FnMut(&[Vpl]), mut far: impl FnMut(&Cluster)) {
        self.visit_nodes(x, stack, near, |c, _, _| far(c))
    }

    /// The VPLs of node `cell` of level `level` (tests: a cluster against its own VPLs).
    #[cfg(test)]
    pub fn members(&self, level: u32, cell: UVec3) -> Vec<Vpl> {
        let base_dims = self.levels[0].dims;
        let lo = cell << level;
        let hi = ((cell + UVec3::ONE) << level).min(base_dims);
        let mut out = Vec::new();
        for z in lo.z..hi.z {
            for y in lo.y..hi.y {
                for x in lo.x..hi.x {
                    let i = cell_index(base_dims, UVec3::new(x, y, z));
                    out.extend_from_slice(&self.vpls[self.start[i] as usize..self.start[i + 1] as usize]);
                }
            }
        }
        out
    }

    /// `visit`, the far nodes with their level and cell.
    pub fn visit_nodes(&self, x: Vec3, stack: &mut Vec<(u32, UVec3)>, mut near: impl FnMut(&[Vpl]), mut far: impl FnMut(&Cluster, u32, UVec3)) {
        let q = self.world_to_index.transform_point3(x);
        stack.clear();
        let top = self.levels.len() as u32 - 1;
        let dims = self.levels[top as usize].dims;
        for z in 0..dims.z {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    stack.push((top, UVec3::new(x, y, z)));
                }
            }
        }
        while let Some((l, c)) = stack.pop() {
            let level = &self.levels[l as usize];
            let node = &level.nodes[cell_index(level.dims, c)];
            if node.power == Vec3::ZERO {
                continue;
            }
            // The node's box in gather index units: gather cell i spans i -/+ 0.5.
            let side = (self.base << l) as f32;
            let lo = c.as_vec3() * side - 0.5;
            let gap = (lo - q).max(q - (lo + side)).max(Vec3::ZERO);
            // Only base cells are taken as clusters (`MAX_CLUSTER_LEVEL`); the levels above
            // only skip what is empty.
            if l <= MAX_CLUSTER_LEVEL && gap.length() * self.min_spacing >= self.opening * side * self.max_spacing {
                far(node, l, c);
            } else if l == 0 {
                let i = cell_index(level.dims, c);
                near(&self.vpls[self.start[i] as usize..self.start[i + 1] as usize]);
            } else {
                let below = self.levels[l as usize - 1].dims;
                for o in 0..8u32 {
                    let child = c * 2 + UVec3::new(o & 1, (o >> 1) & 1, o >> 2);
                    if child.cmplt(below).all() {
                        stack.push((l - 1, child));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_vpls(n: usize, seed: u64) -> Vec<Vpl> {
        let mut rng = Rng::new(seed, 0);
        (0..n)
            .map(|_| {
                let position = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 10.0;
                let incident = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.2).normalize();
                Vpl { position, incident, power: Vec3::new(1.0, 0.5, 0.25) * rng.f32() }
            })
            .collect()
    }

    /// Every VPL is visited once, near or inside exactly one far cluster: the visited power
    /// adds up to the total, and with a huge opening distance every VPL is near.
    #[test]
    fn visit_covers_every_vpl_once() {
        let vpls = random_vpls(5000, 3);
        let total: Vec3 = vpls.iter().map(|v| v.power).sum();
        // The last but one: base cells of 4 gather cells (200 > MAX_BASE).
        for (dims, opening) in [([16, 16, 24], 2.0), ([16, 16, 24], 1.0), ([200, 30, 90], 2.0), ([16, 16, 24], 1e6)] {
            let frame = Affine3A::from_scale(Vec3::splat(10.0) / (UVec3::from_array(dims).as_vec3() - 1.0));
            let tree = FarField::new(&vpls, dims, &frame, opening, None).unwrap();
            let mut stack = Vec::new();
            for x in [Vec3::new(5.0, 5.0, 5.0), Vec3::new(0.1, 9.0, 3.0), Vec3::new(-4.0, 20.0, 5.0)] {
                let (mut near_sum, mut far_sum, mut near_count, mut clusters) = (Vec3::ZERO, Vec3::ZERO, 0usize, 0usize);
                tree.visit(x, &mut stack, |s| {
                    near_count += s.len();
                    near_sum += s.iter().map(|v| v.power).sum::<Vec3>();
                }, |c| {
                    clusters += 1;
                    far_sum += c.power;
                });
                let sum = near_sum + far_sum;
                assert!((sum - total).abs().max_element() < 1e-3 * total.max_element(), "{dims:?} {opening}: {sum} against {total}");
                if opening > 1e5 {
                    assert_eq!((near_count, clusters), (vpls.len(), 0), "{dims:?}: every VPL near");
                } else {
                    assert!(near_count < vpls.len() && clusters > 0, "{dims:?} {opening} at {x}: {near_count} near, {clusters} clusters");
                }
            }
        }
    }

    /// A cluster's moments are its VPLs': centroid, mean incident direction, spread.
    #[test]
    fn cluster_moments() {
        let a = Vpl { position: Vec3::new(1.0, 0.0, 0.0), incident: Vec3::X, power: Vec3::splat(1.0) };
        let b = Vpl { position: Vec3::new(3.0, 0.0, 0.0), incident: Vec3::Y, power: Vec3::splat(3.0) };
        let mut s = Sums::default();
        s.add_vpl(&a);
        s.add_vpl(&b);
        let c = s.cluster();
        assert!((c.centroid - Vec3::new(2.5, 0.0, 0.0)).length() < 1e-6, "{c:?}");
        assert!((c.mean_incident - Vec3::new(0.25, 0.75, 0.0)).length() < 1e-6, "{c:?}");
        // (1 x 1.5^2 + 3 x 0.5^2) / 4
        assert!((c.spread - 0.75).abs() < 1e-5, "{c:?}");
        assert_eq!(c.power, Vec3::splat(4.0));
    }
}
