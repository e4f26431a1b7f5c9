use glam::Vec3;

use super::*;
use crate::network::iterate::tests::plume_point_light;
use volscatter_core::solvers::testing::fixture_scene;
use crate::network::sort::SortParams;
use crate::network::splat::tests::Cancelled;
use crate::test_support::{gpu_or_skip, naga_struct_size};
use volscatter_core::solvers::network::particles;
use volscatter_core::solvers::network::visibility::{self, window_side};
use volscatter_core::stages::NoProgress;
use volscatter_core::medium::optical_depth;
use volscatter_core::translate::sampling::BoundingSphere;
use volscatter_core::Scene;

#[test]
fn network_visibility_wgsl_validates_and_layouts_match() {
    for wgsl in [KEYS_WGSL, LINKS_WGSL] {
        assert_eq!(naga_struct_size(wgsl, "Params") as usize, size_of::<VisibilityParams>());
    }
    assert_eq!(naga_struct_size(sort::WGSL, "Params") as usize, size_of::<SortParams>());
}

/// `d` directions on a golden-angle spiral (the solver's Fibonacci lattice is private to core;
/// any directions serve).
pub(crate) fn spiral(d: usize) -> Vec<Vec3> {
    (0..d)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / d as f32;
            let phi = 2.399_963 * i as f32;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// Per particle of one direction: whether its sort key can change with the rounding of its dot
/// products. WGSL lets a compiler fuse `a.x * b.x + a.y * b.y + a.z * b.z` into multiply-adds
/// (NVIDIA's does; lavapipe does not), which moves a dot product by a few ulp of its terms'
/// magnitudes. A particle is ambiguous when that much moves it across a pixel edge of the
/// window, or leaves its depth within that much of the particle beside it in its pixel's list.
fn ambiguous_keys(p: &[Vec3], (u, v, w): (Vec3, Vec3, Vec3), centre: Vec3, radius: f32, m: u32) -> Vec<bool> {
    // 8 ulp of the sum of the terms' magnitudes: a fused chain rounds twice less, each
    // rounding half an ulp of a partial sum at most.
    let slack = |a: Vec3, b: Vec3| 8.0 * f32::EPSILON * (a * b).abs().element_sum() + f32::MIN_POSITIVE;
    let mut flag: Vec<bool> = p
        .iter()
        .map(|&x| {
            let r = x - centre;
            [u, v].iter().any(|&e| {
                let (a, s) = (r.dot(e), slack(r, e));
                visibility::window_cell(a - s, radius, m) != visibility::window_cell(a + s, radius, m)
            })
        })
        .collect();
    let mut keyed: Vec<(u64, u32, u32)> = p.iter().enumerate().map(|(i, &x)| visibility::sort_key(x, i as u32, (u, v, w), centre, radius, m)).collect();
    keyed.sort_unstable();
    for pair in keyed.windows(2) {
        let (a, b) = (pair[0].2 as usize, pair[1].2 as usize);
        if pair[0].0 == pair[1].0 && (p[b].dot(w) - p[a].dot(w)).abs() <= slack(p[a], w) + slack(p[b], w) {
            flag[a] = true;
            flag[b] = true;
        }
    }
    flag
}

/// The GPU visibility network against core's `visibility::build`, on the fixture cube (g 0.7,
/// a sun) and on the plume lit by a point light, with both opacity modes, at the solver's
/// window (the paper's bound) and at a finer one, with N not a power of two (the sort's
/// padding), in one chunk of directions and in several.
///
/// The lists (order and upstream neighbours) are the CPU's exactly where the GPU computes the
/// keys' dot products as the CPU does (lavapipe: every particle of every case). A compiler that
/// fuses them (an NVIDIA H100, Vulkan driver 580: one list differed, plume, M 30) may move a
/// particle that sits within rounding of a pixel edge or of its neighbour's depth
/// (`ambiguous_keys`): such a particle, and whoever has it as upstream neighbour on either side,
/// is left out of the comparison; every other particle must keep its place in the order and its
/// upstream neighbour, and the ambiguous ones must be rare (under 1%), or the test would see
/// little. The opacities of equal links come from the same march (same steps, same order of
/// summation); they differ by the GPU's exp and density lookup rounding: on lavapipe 1.8e-7 in
/// every case (3 ulp of an opacity near 1). On the H100 the march's fused multiply-adds add up
/// over its steps: 1.4e-6 on the cube, but 4.5e-5 and 1.2e-4 on the plume with
/// `Opacity::Boundary`, where a link's optical depth is the difference of its two particles'
/// depths to the boundary, each up to tens of mean free paths: their rounding, relative to
/// those depths, is what the difference keeps. So the bound is 5e-6 plus 2^-15 (3e-5, some 250
/// ulp) of the two depths (`Opacity::Boundary`; of the gap's own depth with `Segment`), still a
/// fraction of what a wrong neighbour or a missed segment changes (a cell's optical depth).
/// Measured, as a share of each link's bound: lavapipe at most 0.03, the H100 at most 0.23
/// (plume, M 24, Boundary). Every case is measured and printed before any is asserted.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_network_visibility_matches_cpu() {
    let ctx = gpu_or_skip();
    let scenes: [(&str, Scene); 2] = [("cube_g07", fixture_scene("cube_g07")), ("plume + point light", plume_point_light())];
    // With the axis-aligned ones: +-z is where `orthonormal_basis` switches branch.
    let dirs: Vec<Vec3> = spiral(29).into_iter().chain([Vec3::Z, -Vec3::Z, Vec3::X]).collect();
    let mut too_far = Vec::new();
    for (name, sc) in scenes {
        let p = particles::sample(&sc.medium, 1000, 3);
        let sphere = BoundingSphere::of(&sc.medium);
        let paper = window_side(0, 64, sphere.radius, p.mean_sigma_t, p.len());
        for (window, opacity) in [(paper, Opacity::Boundary), (paper, Opacity::Segment), (24, Opacity::Boundary)] {
            let what = format!("{name}, M {window}, {opacity:?}");
            let input = VisibilityInput { medium: &sc.medium, particles: &p, dirs: &dirs, centre: sphere.center, radius: sphere.radius, window, opacity };
            let cpu = visibility::build(&sc.medium, &p, &dirs, sphere.center, sphere.radius, window, opacity, &NoProgress).unwrap();
            let gpu = visibility(&ctx, &input, &NoProgress).unwrap();
            // In chunks of 3 directions (the last one of 2): the same lists.
            let chunked = visibility_chunked(&ctx, &input, 3 * 1024, &NoProgress).unwrap();
            assert!(chunked.iter().zip(&gpu).all(|(a, b)| a.order == b.order && a.up == b.up && a.alpha == b.alpha), "{what}: chunks changed the lists");
            assert_eq!(gpu.len(), cpu.len());
            let (mut worst, mut worst_ratio, mut deepest, mut linked, mut ambiguous, mut differing) = (0.0f32, 0.0f32, 0.0f32, 0usize, 0usize, 0usize);
            let step = visibility::march_step(&sc.medium);
            for (d, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
                let w = dirs[d];
                let (u, v) = volscatter_core::sampling::orthonormal_basis(w);
                let flag = ambiguous_keys(&p.position, (u, v, w), sphere.center, sphere.radius, window);
                ambiguous += flag.iter().filter(|&&f| f).count();
                let mut sorted = g.order.clone();
                sorted.sort_unstable();
                assert!(sorted.iter().enumerate().all(|(i, &k)| k as usize == i), "{what}: direction {d}: the order is not a permutation");
                if g.order != c.order || g.up != c.up {
                    differing += 1;
                }
                let clear = |order: &[u32]| order.iter().copied().filter(|&k| !flag[k as usize]).collect::<Vec<_>>();
                assert_eq!(clear(&g.order), clear(&c.order), "{what}: direction {d}: list order of the unambiguous particles");
                let is_flagged = |k: u32| k != visibility::NONE && flag[k as usize];
                linked += c.up.iter().filter(|&&u| u != visibility::NONE).count();
                for (i, (gu, cu)) in g.up.iter().zip(&c.up).enumerate() {
                    if flag[i] || is_flagged(*gu) || is_flagged(*cu) {
                        continue;
                    }
                    assert_eq!(gu, cu, "{what}: direction {d}: upstream neighbour of particle {i}");
                }
                let depth = |x: Vec3| optical_depth(&sc.medium, x, -w, f32::INFINITY, step, visibility::BOUNDARY_STEPS).max_element();
                for (i, (a, b)) in g.alpha.iter().zip(&c.alpha).enumerate() {
                    if g.up[i] != c.up[i] {
                        continue;
                    }
                    let diff = (*a - *b).abs().max_element();
                    // The rays whose rounding the link's depth carries: Boundary, both
                    // particles' to the boundary; Segment, the gap's (at most that of the
                    // upstream particle's ray, which covers it).
                    let rays = match (opacity, c.up[i]) {
                        (Opacity::Boundary, u) if u != visibility::NONE => depth(p.position[i]) + depth(p.position[u as usize]),
                        _ => depth(p.position[i]),
                    };
                    let bound = 5e-6 + rays * (1.0 / 32768.0);
                    worst = worst.max(diff);
                    deepest = deepest.max(rays);
                    worst_ratio = worst_ratio.max(diff / bound);
                }
            }
            eprintln!("{what}: {linked} links, {ambiguous} ambiguous keys, {differing} of {} directions' lists differ, largest opacity difference {worst:e} (at most {worst_ratio:.3} of a link's bound; rays' depths up to {deepest:.1})", dirs.len());
            assert!(linked > dirs.len() * p.len() / 2, "{what}: only {linked} links: the test would not see wrong neighbours");
            assert!(ambiguous * 100 < dirs.len() * p.len(), "{what}: {ambiguous} ambiguous keys: the comparison would leave out too much");
            if worst_ratio > 1.0 {
                too_far.push(format!("{what}: an opacity differs by {worst_ratio} of its bound (largest difference {worst:e})"));
            }
            assert!(matches!(visibility(&ctx, &input, &Cancelled), Err(Error::Cancelled)));
        }
    }
    assert!(too_far.is_empty(), "{}", too_far.join("; "));
}

/// The sort alone on keys with many ties in the first words (the tie-break the lists rely on)
/// against the host's sort, two lists at once.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_bitonic_sort_matches_host_sort() {
    let ctx = gpu_or_skip();
    let len = 1u32 << 12;
    let mut keys: Vec<[u32; 4]> = (0..2 * len).map(|i| [(i * 7919) % 13, (i * 104_729) % 5, i, 0]).collect();
    let buf = ctx.storage_buffer("sort test keys", bytemuck::cast_slice(&keys)).unwrap();
    sort::sort(&ctx, &buf, len, 2, &NoProgress).unwrap();
    let back = ctx.read_buffer(&buf, 2 * len as u64 * 16).unwrap();
    for list in keys.chunks_mut(len as usize) {
        list.sort_unstable();
    }
    assert_eq!(bytemuck::cast_slice::<u8, [u32; 4]>(&back), &keys[..]);
}

/// A window whose pixels overflow the GPU's 32-bit keys is refused with `Error::Device` (on
/// which `auto` solves on the CPU), never binned wrongly.
#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored all (scripts/test.sh does when one exists)"]
fn gpu_network_visibility_refuses_oversized_windows() {
    let ctx = gpu_or_skip();
    let sc = fixture_scene("cube_g07");
    let p = particles::sample(&sc.medium, 64, 1);
    let sphere = BoundingSphere::of(&sc.medium);
    let dirs = spiral(4);
    let input = VisibilityInput { medium: &sc.medium, particles: &p, dirs: &dirs, centre: sphere.center, radius: sphere.radius, window: 1 << 16, opacity: Opacity::Boundary };
    let e = visibility(&ctx, &input, &NoProgress).err();
    assert!(matches!(e, Some(Error::Device(_))), "{e:?}");
}
