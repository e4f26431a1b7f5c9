//! The cost guard of pop's local lights: each radial source costs a radial grid and its
//! propagation (tens of milliseconds to seconds), so thousands of point lights (a city at
//! night, sparks, an area light cut into many VPLs) would take minutes. Past `MAX_SOURCES`,
//! sources close together are merged into one per cell of a uniform grid over their
//! positions, as coarse as needed to leave at most `MAX_SOURCES`: the power is kept (summed
//! at the power-weighted centroid), and the spread of the merged lights becomes the clamp
//! radius of the merged source (its inverse-square law stops there, as for a VPL standing for
//! a patch), so the medium farther than a cell from them sees the same light. A cone or cosine
//! profile merges as the isotropic intensity of the same power. The solve says so in a note.

use glam::{UVec3, Vec3};

use super::RadialSource;
use crate::translate::emitters::Profile;

/// The radial work a solve takes on before merging, in sources outside the medium. At pop's
/// defaults on a 32^3 plume such a source costs about a quarter of the plume's whole solve
/// under a sun, so 24 keeps a scene within ~10x its preset's median (BENCHMARKS.md, "Cost
/// guard on extreme scenes").
pub const MAX_SOURCES: usize = 24;

/// A source inside the medium's box costs this many outside ones: its grid's shells cross
/// the whole medium from within, and the light diffuses through them for many more
/// iterations (measured: 64 point lights inside the plume took over 90 s, 64 above it 18 s).
pub const INSIDE_COST: usize = 6;

/// The fraction of a source's power an isotropic emitter of the same intensity would emit.
fn power_fraction(p: &Profile) -> f32 {
    match *p {
        Profile::Isotropic => 1.0,
        // The cone's solid angle (between its inner and outer edges, the smoothstep's middle)
        // over the sphere's.
        Profile::Cone { cos_outer, cos_inner, .. } => ((1.0 - 0.5 * (cos_outer + cos_inner)) * 0.5).clamp(0.0, 1.0),
        // A Lambertian patch: pi I of 4 pi I.
        Profile::Cosine { .. } => 0.25,
    }
}

/// `sources`, merged when their cost (one a source, `INSIDE_COST` for one where `inside` says
/// so) is over `max` into groups whose cost is at most `max` (see the module docs), and the
/// note saying what was done (None when nothing was merged).
pub fn cluster(sources: Vec<RadialSource>, max: usize, inside: impl Fn(Vec3) -> bool) -> (Vec<RadialSource>, Option<String>) {
    let max = max.max(1);
    let cost = |p: Vec3| if inside(p) { INSIDE_COST } else { 1 };
    if sources.iter().map(|s| cost(s.position)).sum::<usize>() <= max {
        return (sources, None);
    }
    let (lo, hi) = sources.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(l, h), s| (l.min(s.position), h.max(s.position)));
    let extent = (hi - lo).max(Vec3::splat(1e-6));
    // The finest grid (cells per axis, the same cell size on every axis) that leaves at most
    // `max` occupied cells; occupancy grows with the resolution, so bisect on it.
    // The cost of the groups at `n` cells along the longest axis: a merged group sits at its
    // centroid, which is inside when most of its power is.
    let cost_at = |n: u32| -> usize {
        let h = extent.max_element() / n as f32;
        let dims = (extent / h).ceil().as_uvec3().max(UVec3::ONE);
        let mut groups: std::collections::BTreeMap<u32, (Vec3, usize)> = std::collections::BTreeMap::new();
        for s in &sources {
            let c = ((s.position - lo) / h).floor().as_uvec3().min(dims - 1);
            let g = groups.entry(c.x + dims.x * (c.y + dims.y * c.z)).or_insert((Vec3::ZERO, 0));
            g.0 += s.position;
            g.1 += 1;
        }
        groups.values().map(|(sum, k)| cost(*sum / *k as f32)).sum()
    };
    let (mut good, mut bad) = (1u32, 1024u32);
    if cost_at(bad) <= max {
        good = bad;
    }
    while bad - good > 1 {
        let mid = (good + bad) / 2;
        if cost_at(mid) <= max {
            good = mid;
        } else {
            bad = mid;
        }
    }
    let h = extent.max_element() / good as f32;
    let dims = (extent / h).ceil().as_uvec3().max(UVec3::ONE);
    let mut merged: std::collections::BTreeMap<u32, Vec<&RadialSource>> = std::collections::BTreeMap::new();
    for s in &sources {
        let c = ((s.position - lo) / h).floor().as_uvec3().min(dims - 1);
        merged.entry(c.x + dims.x * (c.y + dims.y * c.z)).or_default().push(s);
    }
    let mut widest = 0.0f32;
    let out: Vec<RadialSource> = merged
        .into_values()
        .map(|group| {
            if group.len() == 1 {
                return *group[0];
            }
            let weight = |s: &RadialSource| (s.emitter.intensity * power_fraction(&s.emitter.profile)).element_sum().max(1e-30);
            let total: f32 = group.iter().map(|s| weight(s)).sum();
            let centre = group.iter().map(|s| s.position * weight(s)).sum::<Vec3>() / total;
            let spread = (group.iter().map(|s| weight(s) * s.position.distance_squared(centre)).sum::<f32>() / total).sqrt();
            let own = group.iter().map(|s| s.emitter.radius.max(s.emitter.clamp_radius)).fold(0.0f32, f32::max);
            widest = widest.max(spread);
            let intensity = group.iter().map(|s| s.emitter.intensity * power_fraction(&s.emitter.profile)).sum::<Vec3>();
            let mut first = *group[0];
            first.kind = "merged lights";
            first.position = centre;
            first.emitter.intensity = intensity;
            first.emitter.profile = Profile::Isotropic;
            first.emitter.radius = 0.0;
            first.emitter.clamp_radius = spread.max(own);
            first
        })
        .collect();
    let note = format!(
        "pop: {} local light sources (point, spot, area VPLs) would take a radial grid each: merged into {} by position \
         (cells of {:.3} m; the widest merged group spreads {:.3} m), with their power; the medium within that distance \
         of the lights sees them blurred",
        sources.len(),
        out.len(),
        h,
        widest
    );
    (out, Some(note))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solvers::pop::radial::init::Emitter;

    fn point(p: Vec3, i: f32) -> RadialSource {
        RadialSource { light: 0, kind: "point", position: p, emitter: Emitter { intensity: Vec3::splat(i), profile: Profile::Isotropic, radius: 0.0, clamp_radius: 0.0, lamp_interior: None } }
    }

    /// 10,000 point lights on a 100 x 100 lattice merge into at most MAX_SOURCES, keeping the
    /// total power and the power-weighted centre; 64 or fewer are left alone.
    #[test]
    fn harden_many_point_lights_merge_keeping_power_and_centre() {
        let lights: Vec<RadialSource> = (0..10_000).map(|k| point(Vec3::new((k % 100) as f32 * 0.1, (k / 100) as f32 * 0.1, 2.0), 1.0 + (k % 7) as f32)).collect();
        let power: Vec3 = lights.iter().map(|s| s.emitter.intensity).sum();
        let centre: Vec3 = lights.iter().map(|s| s.position * s.emitter.intensity.x).sum::<Vec3>() / power.x;
        let (out, note) = cluster(lights, MAX_SOURCES, |_| false);
        assert!(out.len() <= MAX_SOURCES && out.len() >= MAX_SOURCES / 4, "{} sources", out.len());
        assert!(note.unwrap().contains("10000 local light sources"));
        let p2: Vec3 = out.iter().map(|s| s.emitter.intensity).sum();
        // f32 sums of 10^4 terms: 1e-4 relative.
        assert!(((p2 - power) / power).abs().max_element() < 1e-4, "{p2} vs {power}");
        let c2: Vec3 = out.iter().map(|s| s.position * s.emitter.intensity.x).sum::<Vec3>() / p2.x;
        assert!(c2.distance(centre) < 1e-3, "{c2} vs {centre}");
        assert!(out.iter().all(|s| s.emitter.clamp_radius > 0.0 && s.emitter.clamp_radius < 2.0));
        let few: Vec<RadialSource> = (0..MAX_SOURCES).map(|k| point(Vec3::splat(k as f32), 1.0)).collect();
        let (same, note) = cluster(few.clone(), MAX_SOURCES, |_| false);
        assert_eq!(same.len(), MAX_SOURCES);
        assert!(note.is_none());
        // The same lights inside the medium cost INSIDE_COST each: merged to fit.
        let (inside, note) = cluster(few, MAX_SOURCES, |_| true);
        assert!(inside.len() * INSIDE_COST <= MAX_SOURCES && note.is_some(), "{} sources", inside.len());
    }
}
