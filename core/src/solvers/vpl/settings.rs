//! Settings of `vpl`, read from the scene JSON's `solver` block and `--set KEY=VALUE`, and its
//! registry entry. Unknown keys are an error. The measurements behind each default and each
//! choice are in docs/solvers/vpl.md (and the tests in tests.rs).

use crate::solvers::settings_table::{defaults_of, LightType, Make, Preset, SolverEntry};

crate::setting_choices! {
    /// How the 1/d^2 of a VPL's connection is kept finite near the VPL (paper Sec. 4.3).
    #[derive(Default)]
    pub enum NearField {
        /// `hat` where the medium's optical size (`gather::optical_size`) is above
        /// `gather::HAT_ABOVE` (0.9), `ball` below: the hat's density estimate wants the many,
        /// evenly spread VPLs of a medium in which light scatters many times; on thin media the
        /// ball is the closer.
        #[default]
        Auto = "auto",
        /// G = 1 / max(d, r)^2: the paper's clamp. Loses the energy of every connection shorter
        /// than r (not compensated), so S / sigma_s falls below 1 in a furnace.
        Clamp = "clamp",
        /// G = the mean of 1/|y|^2 over a ball of radius r around the VPL
        /// (medium::ball_mean_inverse_square): bounded (3/r^2 at the VPL) and with the same
        /// integral over space as 1/d^2, so no energy is lost, only blurred over r.
        Ball = "ball",
        /// The attenuated top hat (gather.rs `Kernel::Hat`): a VPL within r of a point counts
        /// as a density estimate over the ball, with the mean over the ball of the homogeneous
        /// kernel e^{-sigma d} / d^2 and both phase functions averaged over the ball's
        /// directions; beyond r, T / d^2. Lossless at any optical thickness of the ball, so r
        /// stays a whole gather cell where `ball` must shrink to a fraction of a mean free path.
        Hat = "hat",
        /// The clamp, and the clamped energy put back by the paper's bias compensation
        /// (compensate.rs): new vertices within r of each gather point, connected to subsets of
        /// the walks and to the lights, recursively.
        Compensate = "compensate",
    }
}

crate::setting_choices! {
    /// How the density-guided upsampling estimates J at an output point from its coarse
    /// neighbours (same weights in both).
    pub enum UpsampleFit {
        /// the joint bilateral filter (stages/upsample.rs): the weighted mean, which at a
        /// medium's surface is J at the weights' centroid, inside: bright on a cube, best on
        /// the dense cloud.
        Mean = "mean",
        /// The weighted local linear fit (vpl/upsample.rs): J at the point itself, so the flux
        /// is right at a medium's surface; noisier on the dense cloud.
        Linear = "linear",
    }
}

crate::setting_choices! {
    /// How the gather finds each connection's transmittance (gather.rs, depth_map.rs).
    pub enum Transmittance {
        /// Per gather point, a map of the optical depth along `map_resolution`^2 directions
        /// (depth_map.rs), looked up for the VPLs beyond two gather cells, the nearer ones
        /// marched.
        Map = "map",
        /// A deterministic ray march to every VPL (`gather::march_step`).
        March = "march",
    }
}

crate::setting_choices! {
    /// How the near part of J (the light of VPLs within `near_radius` gather cells) reaches the
    /// output points (vpl/near_ratio.rs).
    pub enum NearUpsample {
        /// Upsampled with the rest of J (`upsample_fit`).
        Plain = "plain",
        /// The gather's ball kernel (radius ~ a gather cell) corrected to the output cell's,
        /// the correction a density integral times the near light's level, which is upsampled
        /// as a ratio (near_ratio.rs); deterministic, only with `near_field: ball`. Not the
        /// default: it lifts every flux by 1-2%, a third of what a finer gather gives the local
        /// lights, and makes the cubes (already bright) worse.
        Ratio = "ratio",
    }
}

crate::settings! {
    pub struct VplSettings {
        /// The noise of the multiple scattering falls as 1 / sqrt(walks); the gather's cost
        /// grows with it.
        walks: u32 = 4096, range(>= 1, <= 1u32 << 24),
            "random walks from the lights (noise falls as 1/sqrt)";
        /// A bias reached only in very thick white media: Russian roulette ends walks first
        /// elsewhere.
        max_vertices: u32 = 4096, range(>= 1, <= 1u32 << 20),
            "most VPLs one walk leaves before it is cut";
        /// Roulette on the walk's throughput relative to its start: fewer long, dim walks,
        /// unbiased.
        rr_depth: u32 = 4,
            "scattering vertices before Russian roulette starts";
        /// Sec. 4.2: subsets interleaved over the grid in 2x2x2 blocks, averaged by the
        /// upsampling's filter. Off by default: fewer walks per point see fewer of the rare
        /// close VPLs that carry the dense parts' light, a heavy-tailed estimate that comes
        /// out dark.
        walks_per_subset: u32 = 0, zero("every point uses every walk"),
            "walks per interleaved subset gathered at each point";
        /// See `NearField`; `auto` picks the kernel that is closer on the medium at hand.
        near_field: NearField = NearField::Auto,
            "near field of 1/d^2: auto (hat or ball, by the medium), the clamp at the radius, the lossless ball kernel, the attenuated top hat, or the clamp with bias compensation";
        /// The first recursion level; one per vertex below it.
        compensation_vertices: u32 = 4, range(>= 1, <= 256),
            "compensation: new vertices per gather point";
        compensation_depth: u32 = 2, range(>= 1, <= 8),
            "compensation: recursion levels (the last takes the VPLs with the ball kernel)";
        /// One random subset of the walks, reweighted.
        compensation_walks: u32 = 256, range(>= 1, <= 1u32 << 24),
            "compensation: walks each new vertex connects to";
        /// In units of the radius of the ball with one gather cell's volume
        /// (medium::near_field_radius): the clamp radius of `clamp` and `compensate`, the
        /// largest ball of `ball`.
        clamp_radius: f32 = 1.0, range(> 0, <= 16),
            "near-field radius, in gather-cell radii";
        /// The ball kernel is lossless only where the transmittance is flat over the ball; in
        /// a cell many mean free paths thick a ball of a cell loses most of the light.
        mean_free_paths: f32 = 0.25, range(>= 0),
            "the ball kernel's radius is at most this many local mean free paths (0: no limit)";
        /// Where the ball is a fraction of a mean free path, a rare VPL in line with the camera
        /// gives two sharp g 0.9 lobes times 3 / r^2 and outweighs the rest (a heavy tail);
        /// capped at a quarter cell because on thin media smoothing over a whole cell blurs
        /// the angular distribution the gather resolves.
        phase_cone: f32 = 0.25, range(>= 0, <= 16),
            "ball kernel: radius, in gather-cell radii, below which both phase functions are smoothed to the ball's cone (0: off)";
        /// Corrects the global share of the coarse gather's bias (energy.rs), for one more
        /// upsampling of the gather grid. Ignored with `near_field: compensate` or `hat`
        /// (lossless by construction), `near_refine` and `near_upsample: ratio`.
        normalize_energy: bool = true,
            "scale the multiple scattering so that the power it scatters equals the walks' (not with compensate, near_refine or near_upsample ratio)";
        /// `map` changes no fixture's error beyond the third decimal and makes the gather 4-7x
        /// cheaper. The compensation's and `near_refine`'s connections are marched either way.
        transmittance: Transmittance = Transmittance::Map,
            "each connection's transmittance: from a per-point optical-depth map beyond one gather cell, or marched to every VPL (the GPU always marches)";
        /// Octahedral; 8 is as exact as 16 on the default scene's image, and cheaper.
        map_resolution: u32 = 8, range(>= 2, <= 64),
            "transmittance map: n x n directions per gather point";
        /// far_field.rs: each farther cell's VPLs at their centroid, their lobes as |m| whole
        /// lobes about their mean incident direction and the rest isotropic. Cells and not
        /// larger nodes: far_field.rs `MAX_CLUSTER_LEVEL`. The GPU connects every VPL.
        cluster_distance: f32 = 2.0, range(>= 0.5, <= 16), zero("every VPL one by one"),
            "far VPLs as clusters: connected one by one only within this many gather cells, each farther cell's VPLs once (CPU only)";
        /// Its cells set a bias besides the cost: the light a point gets from VPLs within a
        /// cell correlates with the density there, which a coarse J loses (local lights come
        /// out dark). The gather's cost grows with its cube.
        gather_resolution: u32 = 16, range(>= 2, <= 256),
            "largest side of the coarse gather grid";
        /// The single scattering is computed on it exactly, the gathered multiple scattering
        /// upsampled to it.
        output_resolution: u32 = 64, range(>= 2, <= 1024),
            "largest side of the returned scattering grid";
        /// pop's upsample.rs.
        upsample: bool = true,
            "joint bilateral upsampling guided by the density (off: trilinear)";
        /// See `UpsampleFit`; the mean keeps every fixture's ratchet.
        upsample_fit: UpsampleFit = UpsampleFit::Mean,
            "upsampling's estimate of J: the weighted mean, or a weighted linear fit (flux right at a medium's surface)";
        /// refine.rs. Off by default: it puts the local lights' flux right, but each output
        /// point sees few VPLs within the radius, so the image is noisier at equal walks.
        near_refine: f32 = 0.0, range(>= 0.5, <= 4), zero("off"),
            "radius in gather cells within which the VPLs are gathered at each output point, not upsampled";
        /// See `NearUpsample`; ignored with `near_refine` and without `upsample`.
        near_upsample: NearUpsample = NearUpsample::Plain,
            "near field at the output points: upsampled with the rest, or the gather's ball kernel corrected to the output's from the density (ratio)";
        /// The VPLs within r_n / 2 (fading out at r_n) set the near light's level; it barely
        /// matters.
        near_radius: f32 = 1.5, range(>= 0.5, <= 4),
            "near_upsample ratio: radius in gather cells of the near part that sets the light's level";
        range_sigma: f32 = 0.15, range(> 0),
            "range sigma of the bilateral filter, a fraction of the largest density";
        /// At least ~0.8, so that the interleaved subsets of neighbouring points are averaged.
        spatial_sigma: f32 = 0.8, range(> 0, <= 4),
            "spatial sigma of the bilateral filter, in gather cells";
        /// stages::single_scattering::single_scattering_grid.
        dome_directions: u32 = 32, range(>= 1, <= 1024),
            "dome directions of the exact single scattering";
        /// The sky's single scattering is smooth: marched on a coarser grid and interpolated
        /// trilinearly (stages::single_scattering::single_scattering_grid_dome_spaced). Only on grids of at
        /// least 64 points (compositor::MIN_DOME_POINTS); the GPU takes every point.
        dome_spacing: u32 = 2, range(>= 1, <= 8),
            "the single scattering's sky marched on every n-th output point and blended between (CPU only, grids of 64 points or more)";
        /// Walk w uses stream w of this seed, so consecutive frames share their paths.
        seed: u64 = 1,
            "random seed (walk w is stream w: deterministic for a seed)";
    }
}

pub const ENTRY: SolverEntry = SolverEntry {
    name: "vpl",
    label: "Virtual Point Lights",
    help: "instant multiple scattering with virtual point lights (paper 03): random walks from the lights leave VPLs that are gathered on a coarse grid, with exact single scattering",
    settings: VplSettings::SETTINGS,
    defaults: defaults_of::<VplSettings>,
    lights: &LightType::ALL,
    presets: &[
        Preset::draft(r#"{"walks": 1024, "gather_resolution": 12, "output_resolution": 48}"#),
        Preset::preview(r#"{"walks": 4096, "gather_resolution": 16, "output_resolution": 64}"#),
        Preset::final_(r#"{"walks": 16384, "gather_resolution": 24, "output_resolution": 128}"#),
    ],
    // furnace.rs's (its bounds were measured with them).
    test: Preset::test(r#"{"walks": 2048, "gather_resolution": 10, "output_resolution": 12}"#),
    make: Make::Solver(|m| Ok(Box::new(super::Vpl::from_settings(m)?))),
    gpu: true,
};

impl VplSettings {
    /// Number of interleaved walk subsets (at least 1, at most `walks`).
    pub fn subsets(&self) -> u32 {
        if self.walks_per_subset == 0 { 1 } else { (self.walks / self.walks_per_subset.max(1)).clamp(1, self.walks) }
    }
}

impl VplSettings {
    /// The settings of the shared upsampling stage (stages/upsample.rs), declared here with the
    /// same names and ranges as in every solver that upsamples.
    pub fn upsampling(&self) -> crate::stages::upsample::Upsampling {
        crate::stages::upsample::Upsampling { output_resolution: self.output_resolution.into(), upsample: self.upsample, range_sigma: self.range_sigma, spatial_sigma: self.spatial_sigma }
    }
}
