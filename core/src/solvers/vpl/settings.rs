//! `vpl` settings, each with what it changes (measured effects in tests.rs and the module doc).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// How the 1/d^2 of a VPL's connection is kept finite near the VPL (paper Sec. 4.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NearField {
    /// G = 1 / max(d, r)^2: the paper's clamp. Loses the energy of every connection shorter
    /// than r (not compensated in this landing), so S / sigma_s falls below 1 in a furnace.
    Clamp,
    /// G = the mean of 1/|y|^2 over a ball of radius r around the VPL
    /// (medium::ball_mean_inverse_square): bounded (3/r^2 at the VPL) and with the same
    /// integral over space as 1/d^2, so no energy is lost, only blurred over r.
    Ball,
    /// The attenuated top hat (gather.rs `Kernel::Hat`): a VPL within r of a point counts
    /// as a density estimate over the ball, with the mean over the ball of the homogeneous
    /// kernel e^{-sigma d} / d^2 (sigma the point's extinction) and both phase functions
    /// replaced by their mean over the ball's directions (HG with g^2 from the VPL's incident
    /// direction to the viewer); beyond r, T / d^2. Lossless at any optical thickness of the
    /// ball, so r stays a whole gather cell where `ball` must shrink to a fraction of a mean
    /// free path (`mean_free_paths`) and turns heavy-tailed.
    Hat,
    /// `ball` or `hat` by the medium: the hat where its optical size (`gather::optical_size`:
    /// the mean free paths a 16th of its extent spans where light scatters) is above
    /// `gather::HAT_ABOVE` (0.9), the ball below, at every gather resolution. Measured optical
    /// sizes: cubes 0.18, the plume and its local lights 0.28-0.42, the benchmark smokes
    /// 0.18-0.27, the default scene 0.62 (all: ball, their results unchanged), the benchmark's
    /// Blender dense cloud 1.20 and the dense cloud fixture 2.0 (hat). Why the medium's and
    /// not the gather cell's thickness: the hat is better on the dense clouds at every gather
    /// resolution (benchmark dense cloud at draft / preview / final, 12 / 16 / 24 cells: image
    /// 0.400 / 0.271 / 0.315 against the ball's 0.441 / 0.344 / 0.601; the fixture cloud, 8
    /// seeds at 32768 walks: x0.998 +- 0.010 with image errors 0.14-0.23 against x1.080 +-
    /// 0.038 with 0.25-0.80), but worse on the default scene at 12 cells, where its cells are
    /// as thick as the benchmark cloud's at 24 (64 x 64 pixels, 16384 walks: 0.095 x0.935
    /// against the ball's 0.087 x0.981; at 16 cells 0.081 x0.967 against 0.086 x0.992):
    /// the hat's density estimate wants the many, evenly spread VPLs of a medium in which light
    /// scatters many times. On the thin fixtures the hat's 8-seed flux (defaults, 4096 walks)
    /// misses 2% where the ball's meets it: plume x1.109 (ball x0.997), cube g 0 x1.026
    /// (x1.007), cube g 0.7 x1.026 (x1.015); spot x0.989, point light x0.985 (32768 walks).
    #[default]
    Auto,
    /// The clamp, and the clamped energy put back by the paper's bias compensation
    /// (compensate.rs): new vertices within r of each gather point, connected to subsets of
    /// the walks and to the lights, recursively.
    Compensate,
}

/// How the density-guided upsampling estimates J at an output point from its coarse
/// neighbours (same weights in both).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UpsampleFit {
    /// pop's joint bilateral filter (pop/upsample.rs): the weighted mean, which at a medium's
    /// surface is J at the weights' centroid, inside: the image bright on cube g 0 (8 seeds
    /// x1.079), but the dense cloud's image error lowest (0.746).
    Mean,
    /// The weighted local linear fit (vpl/upsample.rs): J at the point itself (8 seeds on cube
    /// g 0 x1.013); at its tests' settings the image error is lower on the cubes (g 0 0.054
    /// against 0.076, g 0.7 0.119 against 0.153) and equal on the local lights, but higher on
    /// the dense cloud (0.866, over its ratchet) and darker around a point light inside a g 0
    /// sphere (fig10_g0, 8 seeds x0.917 against the mean's x1.132).
    Linear,
}

/// How the gather finds each connection's transmittance (gather.rs, depth_map.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Transmittance {
    /// A deterministic ray march to every VPL (`gather::march_step`).
    March,
    /// Per gather point, a map of the optical depth along `map_resolution`^2 directions
    /// (depth_map.rs), looked up for the VPLs beyond two gather cells, the nearer ones marched.
    Map,
}

/// How the near part of J (the light of VPLs within `near_radius` gather cells) reaches the
/// output points (vpl/near_ratio.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NearUpsample {
    /// Upsampled with the rest of J (`upsample_fit`).
    Plain,
    /// The gather's ball kernel (radius ~ a gather cell) corrected to the output cell's, the
    /// correction a density integral times the near light's level, which is upsampled as a
    /// ratio (near_ratio.rs); deterministic, no per-point VPL noise; only with `near_field:
    /// ball` (the other kernels are left as they are). Measured, the same walks plain ->
    /// ratio (image mean ratio over 8 seeds, 16-cell gather, 64-cell output): plume_point
    /// 4096 walks x0.877 -> x0.891, 32768 walks x0.934 -> x0.950 (+- 0.009; a 32-cell gather
    /// x0.980); plume_spot 8192 walks x0.934 -> x0.949 (+- 0.004); cube_g0 1024 walks x1.041
    /// -> x1.044. At the ratchets' settings (4096 walks, 12 cells, seed 1; image rel. RMSE,
    /// ratio): plume_point 0.164 -> 0.156 (x0.867 -> x0.878), plume_spot 0.143 -> 0.136
    /// (x0.914 -> x0.926), plume_rect 0.191 -> 0.185 (x0.896 -> x0.908), plume 0.362 -> 0.373
    /// (x0.923 -> x0.940), dense cloud 0.746 -> 0.747, cube g 0 0.076 -> 0.087 (x1.059 ->
    /// x1.077), cube g 0.7 0.153 -> 0.166 (x1.082 -> x1.104). Default scene (256 x 256, 4096
    /// walks): mean RGB +0.5%, 4.27 -> 4.83 s (the stage 0.77 s on 2 cores). Not the default:
    /// it lifts every flux by 1-2% (what the ball kernel loses where the medium attenuates over
    /// a cell, and where the density peaks within it), a third of what a finer gather gives
    /// the local lights, and makes the cubes (already bright by the mean fit's surface bias)
    /// worse; around a point light inside a g 0 sphere (fig10_g0, 4096 walks, 4 seeds) x1.082
    /// -> x1.104, where a 32-cell gather gives x1.022: there the finer gather is darker (the
    /// fluence peaks within a cell, which the model's smooth phi does not follow) and the
    /// correction goes the other way. With `upsample_fit: linear` (16 cells, 8 seeds):
    /// cube_g0 1024 walks x1.009 -> x1.013, plume_point 4096 walks x0.894; the dense cloud is
    /// unchanged by the ratio (its ball, a quarter mean free path, is below an output cell, so
    /// the kernels agree), so the linear fit's excess there (0.866 against the ratchet's
    /// 0.816) stays: linear + ratio is no default either. Where the local lights' darkness comes from, measured on the way (plume_point,
    /// 4096 walks, plain): a 16-cell gather with half the ball radius (clamp_radius 0.5, no
    /// mean-free-path limit) x0.904 equals the 32-cell gather x0.899 (4 seeds, the same walks),
    /// so it is the ball kernel's radius, not the upsampling; and the first form of this stage,
    /// the near light's sub-cell correlation with the density through the gather's own kernel
    /// (D_b at the output points over D_b at the coarse points), changed it by -0.001 (2
    /// seeds).
    Ratio,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VplSettings {
    /// Random walks started from the lights (the number of light paths): the noise of the
    /// multiple scattering falls as 1 / sqrt(walks), the gather's cost grows with it.
    pub walks: u32,
    /// Most scattering vertices (VPLs) one walk leaves before it is cut (a bias, reached only
    /// in very thick white media: Russian roulette ends walks first elsewhere).
    pub max_vertices: u32,
    /// Scattering vertices before Russian roulette starts (on the walk's throughput relative
    /// to its start): fewer long, dim walks, unbiased.
    pub rr_depth: u32,
    /// Walks per interleaved subset (Sec. 4.2): each gather point connects to one subset of
    /// walks, the subsets interleaved over the grid in 2x2x2 blocks, and the upsampling's
    /// filter averages neighbouring subsets. 0 = every point uses every walk (no interleave),
    /// the default: measured on the plume at 32768 walks, 8 subsets made the gather 7.6x
    /// cheaper (0.61 s against 4.58 s) but the image 21% too dark (mean x0.79 against x1.02),
    /// since fewer walks per point see fewer of the rare close VPLs that carry the dense
    /// parts' multiple scattering (a heavy-tailed estimator: its typical value is below its
    /// mean until enough walks are gathered).
    /// A lead, measured later (not yet a default; vpl_explore_seeds with VPL_WPS, 64-cell
    /// output, image mean ratio over 4 seeds +- standard error, time per solve on 2 cores):
    /// a 32-cell gather with 8 subsets of 4096 walks (32768 walks) against the defaults (16
    /// cells, 4096 walks, no subsets): cube_g0 x1.001 +- 0.003 (image 0.025-0.032) against
    /// x0.986 +- 0.012 (0.044-0.068), 2.0 s against 1.9 s; plume_point x0.972 +- 0.012 against
    /// x0.878 +- 0.013, 0.29 s against 0.07 s; plume x0.989 +- 0.031 against x0.850 +- 0.040,
    /// 1.4 s against 0.3 s; cube_g07 (2 seeds) x0.989 against x0.984; the dense cloud (2
    /// seeds) x0.72 against x0.44 but one seed's image 1.01 (a heavy tail) against 0.63-0.75,
    /// 14 s against 3 s. 64 subsets of 512 walks at the same 32 cells are heavy-tailed (plume
    /// one seed x2.6). On plume_point the 16-cell gather stays dark with more walks (262144
    /// walks x0.938 +- 0.008), a 32-cell gather with every walk reaches x0.985 (2 seeds, 17 s):
    /// the gather's resolution, not the walks, sets that flux; of it the ball kernel's radius
    /// is about half (no mean-free-path limit, 262144 walks: radius 1 / 0.5 / 0.25 cells
    /// x0.917 / 0.953 / 0.963; `near_upsample: ratio` at radius 1 x0.948). At host image
    /// sizes (vpl_bench_image, VPL_GATHER=32, 8 subsets; against BENCHMARKS.md vpl-image's
    /// defaults) it is no clear win: the default scene 256 x 256 at 8192 / 32768 / 131072 walks
    /// 1.4 / 4.0 / 13.8 s, image 0.346 / 0.150 / 0.074, x1.022 / 0.970 / 0.964 (defaults:
    /// 16384 walks 3.4 s 0.114 x0.926, 65536 11.9 s 0.090 x0.928); plume_point 128 x 128 at
    /// 32768 / 131072 walks 0.31 / 1.11 s, 0.140 / 0.088, x0.947 / 0.940 (defaults 16384 0.29 s
    /// 0.106 x0.950, 65536 1.02 s 0.086 x0.939).
    pub walks_per_subset: u32,
    /// Near-field handling of the VPL connections (see `NearField`). `auto`, the default: the
    /// hat on media in which light scatters many times (optical size over 0.9; the dense
    /// cloud: 8 seeds at 32768 walks x0.998 with image errors 0.14-0.23, against the ball's
    /// x1.080 with 0.25-0.80; 4096 walks, 12-cell gather: image 0.42 against 0.71), the ball
    /// on every other fixture, where it was the default before the hat, because at equal cost
    /// it is as good or better on every fixture (scripts/bench_vpl.py,
    /// BENCHMARKS.md `vpl`, 8192 walks): cube g 0.7 0.114 (compensate 0.112), point light
    /// beside the plume 0.16 (0.19), dense cloud 0.57 with flux x0.80 (0.58, x0.59), and on the
    /// plume the compensation is heavy-tailed (one run 1.47, flux x1.62; ball 0.41); its
    /// 8-seed flux on cube g 0 is x1.08 (compensate x1.11) and the energy balance 1.0345
    /// (compensate 1.0725). `compensate` is what a furnace lit from everywhere wants (white
    /// furnace box S / sigma_s 0.996 against the ball's 0.957 and the clamp's 0.824) and stays
    /// a setting; it costs 1.3x (plume) to 1.8x (cube, cloud) the ball's gather time.
    pub near_field: NearField,
    /// Radius r of the near field, in units of the gather grid's cell radius (the radius of
    /// the ball with one gather cell's volume, medium::near_field_radius): the clamp radius R
    /// of `clamp` and `compensate`, the largest ball of `ball` (and of `compensate`'s last
    /// level).
    pub clamp_radius: f32,
    /// `near_field: ball`: the largest radius, in gather-cell radii, over which both phase
    /// functions of a connection are smoothed to the cone of the ball around the VPL
    /// (gather.rs `Kernel::Ball`): at each point min(ball radius, this); 0 = off. Why: where the
    /// ball is a fraction of a mean free path (the dense cloud: a quarter), a VPL within a few
    /// ball radii of a point gives up to 3 / r^2 times two g 0.9 lobes (each peaks at 190x the
    /// isotropic 1 / 4 pi), so a rare VPL behind a point, in line with the camera, outweighs the rest:
    /// a heavy tail whose typical seed is dark and whose rare seed is many times too bright.
    /// Measured (vpl_explore_seeds, defaults, 8 seeds, image mean ratio +- standard error, the
    /// seeds' image rel. RMSE): dense cloud without x1.395 +- 0.83 (typical seeds x0.39-0.67,
    /// one seed x7.2 with image error 22), cone at the whole ball x0.953 +- 0.070 (errors
    /// 0.44-1.13), at a quarter cell x0.965 +- 0.069 (0.48-1.13). Capped because on thin media
    /// the ball is a whole cell and smoothing the lobes over it blurs the angular distribution
    /// the gather resolves (with the energy normalization): the spot beside the plume without
    /// x0.969, cone at the whole ball x1.063, half x1.001, a quarter x0.978; capped at a quarter
    /// cell: spot x0.984, point light x0.943 (without x0.926), rect light x0.955 (x0.936),
    /// plume x1.000 (x0.909), cube g 0.7 x1.012 (x1.010); only one lobe smoothed does not
    /// remove the cloud's tail (view lobe alone x1.08 +- 0.17, the VPL's alone x0.85 +- 0.15).
    /// Default scene 256 x 256 (vpl_bench_image): image error 0.146 -> 0.129 at 4096 walks,
    /// 0.105 -> 0.087 at 16384, flux x0.913 -> x0.964 and x0.943 -> x0.992.
    pub phase_cone: f32,
    /// The ball kernel's radius is also kept below this many mean free paths of the point
    /// (1 / sigma_t of its cell's mean density); 0 = no such limit. Why: the ball kernel is
    /// lossless only where the transmittance is flat over the ball; in a cell many mean free
    /// paths thick (the dense cloud) a ball of a cell lost most of the multiple scattering
    /// (white cloud furnace S / sigma_s 0.035 at 10 gather cells, measured). The clamp radius
    /// R is not limited: what the clamp takes is what the compensation restores.
    pub mean_free_paths: f32,
    /// `near_field: compensate`: new vertices around each gather point (the first recursion
    /// level; one per vertex below it).
    pub compensation_vertices: u32,
    /// `near_field: compensate`: recursion levels; at the last the vertices take the VPLs with
    /// the ball kernel instead of the clamp (1: no recursion).
    pub compensation_depth: u32,
    /// `near_field: compensate`: walks each new vertex connects to (one random subset of the
    /// walks, reweighted).
    pub compensation_walks: u32,
    /// Largest side of the coarse grid on which VPLs are gathered. Its cells set a bias besides
    /// the cost: the light a point gets from VPLs within a cell correlates with the density
    /// there (both sit in the dense wisps), which a coarse J loses, so local lights beside the
    /// plume come out dark (plume_point, 32768 walks, 4 seeds: 12 / 16 / 24 / 32 cells x0.920 /
    /// 0.937 / 0.962 / 0.980) and cube_g0 with the mean fit bright (x1.079 / 1.040 / 1.008 at
    /// 12 / 16 / 24); the gather's cost grows with the cube of it (tests.rs, above
    /// `vpl_eight_seeds_flux_within_two_percent`).
    pub gather_resolution: u32,
    /// Largest side of the returned scattering grid (the single scattering is computed on it
    /// exactly, the gathered multiple scattering upsampled to it).
    pub output_resolution: u32,
    /// Joint bilateral upsampling guided by the density (pop's upsample.rs); off: trilinear.
    pub upsample: bool,
    /// With `upsample`: the weighted mean (pop's filter, the default: it keeps every fixture's
    /// ratchet) or the weighted local linear fit (flux right at a medium's surface; see
    /// `UpsampleFit` for both's measured errors).
    pub upsample_fit: UpsampleFit,
    /// Radius r_n, in gather cells, within which the VPLs' light is gathered at each output
    /// point instead of upsampled from the coarse grid (refine.rs: the light from VPLs within
    /// a cell correlates with the density there, which a coarse J loses); 0 = off, the
    /// default. Measured on plume_point (12-cell gather, 32768 walks, 4 seeds, image mean
    /// ratio): off x0.920, 1.5 x0.957, 3 x0.973, 4 x0.973, at 1.3x / 2.1x / 3.6x the solve's
    /// time; but at the ratchets' 4096 walks the finer near part is noisier (image rel. RMSE
    /// plume 0.561 against 0.365, cloud 1.18 against 0.75, cube g 0.7 0.137 against 0.153).
    /// On the default scene at 256 x 256 (BENCHMARKS.md vpl-image, 64-cell output) r_n 3 puts
    /// the flux right (x0.987 / 0.951 / 0.993 at 1024 / 4096 / 16384 walks, off: x0.871 /
    /// 0.871 / 0.926) but its image error is higher (0.71 / 0.29 / 0.17 against 0.31 / 0.17 /
    /// 0.11) at 1.3-2.6x the time: each output point sees few VPLs within r_n.
    pub near_refine: f32,
    /// How the near part of J reaches the output points (`NearUpsample`, near_ratio.rs);
    /// ignored with `near_refine` (which gathers the near part at the output points instead)
    /// and without `upsample`.
    pub near_upsample: NearUpsample,
    /// r_n of `near_upsample: ratio`, in gather cells: the VPLs within r_n / 2 (fading out at
    /// r_n) set the near light's level. Barely matters: plume_point (32768 walks, 8 seeds)
    /// 0.75 / 1.5 / 3 cells x0.9504 / 0.9503 / 0.9495.
    pub near_radius: f32,
    /// Scale the multiple scattering so that the power it scatters equals the power the walks
    /// scattered after their first collision (energy.rs): corrects the share of the coarse
    /// gather's bias that is global, at the cost of one more upsampling of the gather grid.
    /// Ignored with `near_field: compensate` or `hat` (lossless by construction: on the dense
    /// cloud, 8 seeds at 32768 walks, x0.998 without, x0.960 with), `near_refine` and
    /// `near_upsample: ratio`.
    /// Measured (vpl_explore_seeds, defaults without `phase_cone`, 8 seeds, image mean ratio
    /// off -> on, the factor's range): plume_point (4096 walks) x0.878 (4 seeds) -> x0.926,
    /// factors 1.00-1.13; at 32768 walks (4 seeds) x0.934 -> x0.970, 1.05-1.08 (a bias of the
    /// coarse gather, not noise); spot light x0.931 -> x0.969, 1.03-1.07; plume x0.850 -> x0.909;
    /// cube g 0 x0.986 (4 seeds) -> x1.004, 0.99-1.01; cube g 0.7 x1.010, 1.00-1.02. Default
    /// scene 256 x 256 (vpl_bench_image): image rel. RMSE 0.176 -> 0.146 at 4096 walks, 0.116
    /// -> 0.105 at 16384, flux x0.871 -> x0.913 and x0.926 -> x0.943, time unchanged within
    /// noise. What it leaves is where the light lands: the local lights are still a few per
    /// cent dark, a finer gather's share (32 cells with 8 interleaved subsets of 4096 walks,
    /// with it: spot x0.997, rect x0.977, point x0.988, cube g 0 x1.006, 4 seeds).
    pub normalize_energy: bool,
    /// How the gather's connections get their transmittance (`Transmittance`; the
    /// compensation's connections and `near_refine`'s are marched either way, and the GPU
    /// marches every connection). `map`, the default, because it changes no fixture's error
    /// beyond the third decimal and makes the gather 4-7x cheaper. Measured, march -> map
    /// (n = 16): default scene 256 x 256 (vpl_bench_image, 2 cores, same run): 4096 walks
    /// 1.33 -> 0.75 s (gather 0.73 -> 0.18 s), image rel. RMSE 0.1286 -> 0.1285; 16384 walks
    /// 3.64 -> 1.07 s (gather 3.03 -> 0.51 s: 17.7M connections, ~340 -> ~57 ns each per core),
    /// 0.0869 -> 0.0869; 65536 walks 12.6 -> 2.41 s (gather 12.0 -> 1.77 s; 2.26 / 1.65 s once
    /// the node lookup was inlined), 0.0440 -> 0.0439,
    /// flux x0.992 both; 131072 walks (map) 4.14 s, 0.0438 (the 16-cell gather's bias floor,
    /// ~0.7% by a fit of error^2 = b^2 + c / walks, which puts 5% at ~50000 walks, ~1.9 s; the
    /// reference reaches 5% in ~21 s: 11x, not the aim's 30x). At equal time the map gives
    /// 0.087 at 1.07 s where the march gives 0.129 at 1.33 s. Fixtures (test settings, 4096 walks,
    /// 12-cell gather; image / grid rel. RMSE march -> map): cube g 0 0.0693 / 0.0671 -> 0.0693
    /// / 0.0672, cube g 0.7 0.1481 / 0.1392 -> 0.1480 / 0.1389, plume 0.3272 / 0.4460 -> 0.3267
    /// / 0.4459, dense cloud 0.7072 / 0.7643 -> 0.7075 / 0.7645, point light 0.1114 / 0.2234
    /// -> 0.1115 / 0.2231; 8 seeds at the defaults unchanged to 0.001 (cube g 0 x1.004, g 0.7
    /// x1.012, plume x0.999, spot x0.984, point x0.986); dense cloud at the defaults (8 seeds,
    /// vpl_explore_seeds) x0.9648 +- 0.069 -> x0.9645 +- 0.070, each seed's image error within
    /// 0.001, 3.1-3.6 -> 0.55-0.64 s a solve. Furnaces (testing/furnace.rs, 2048 walks, 10
    /// cells): white box S / sigma_s 0.9723 -> 0.9722, white cloud 0.7681 -> 0.7689; the
    /// energy balance 1.0500 -> 1.0502 (over its bound of 0.048 with the march as well).
    pub transmittance: Transmittance,
    /// The far VPLs as clusters (far_field.rs): a point connects one by one only to the VPLs
    /// of the gather cells nearer than this many cells, to each farther cell's VPLs once (their
    /// power at their centroid, their lobes as |m| whole lobes about their mean incident
    /// direction m and the rest isotropic, 1/d^2 and the transmittance corrected for their
    /// spread); 0 = every VPL one by one. The CPU gather only (the GPU connects every VPL, as
    /// it marches every connection). Default 2, measured (BENCHMARKS.md vpl-image, 2 cores):
    /// the default scene 256 x 256 reaches 5% image error in 0.65 s (65536 walks 0.68 s, image
    /// 0.042, x0.998) against the path tracer's ~22 s, 34x (before, every VPL one by one: 1.9
    /// s, 11x); the point light beside the plume at 128 x 128 in 0.15 s, 96x (26x). Distance 1
    /// / 1.5 / 2 on the default scene at 65536 walks: image 0.047 / 0.046 / 0.044 (clusters
    /// at every tree level). 8 seeds (`vpl_eight_seeds_flux_*`, 0 -> 2): cube g 0 x1.008, cube
    /// g 0.7 x1.016 -> x1.018, dense cloud x1.001, plume x0.990, point x0.996, rect x0.997,
    /// spot x0.992. Why cells and not larger nodes: far_field.rs `MAX_CLUSTER_LEVEL`.
    pub cluster_distance: f32,
    /// `transmittance: map`: the map's side n (n x n directions, octahedral). Measured: the
    /// transmittance's mean absolute error against a fine march on the plume 0.0057 at n = 16,
    /// 0.0024 at 32 (the march's own 0.0006; depth_map.rs test); default scene 256 x 256, n =
    /// 16 -> 32: 16384 walks 1.07 -> 1.34 s, image 0.0869 -> 0.0869; 65536 walks 2.41 -> 2.58
    /// s, 0.0439 -> 0.0440: 16 is enough there. Default 8 since (65536 walks, `dome_spacing` 2):
    /// default scene gather 0.25 -> 0.15 s, image 0.0444 -> 0.0438; plume_point 0.0547 at 8
    /// and 16 alike, 7-10% faster.
    pub map_resolution: u32,
    /// Range sigma of the bilateral filter, a fraction of the largest density.
    pub range_sigma: f32,
    /// Spatial sigma of the bilateral filter, in gather cells: at least ~0.8 so that the
    /// interleaved subsets of neighbouring points are averaged.
    pub spatial_sigma: f32,
    /// Dome directions of the exact single scattering (compositor::single_scattering_grid).
    pub dome_directions: u32,
    /// The single scattering's dome part on a grid this many output cells apart, interpolated
    /// trilinearly (compositor::single_scattering_grid_dome_spaced; 1: at every output point).
    /// The CPU only (the GPU's grid takes the dome at every point), and only on grids of at
    /// least 64 points (compositor::MIN_DOME_POINTS). Default 2, measured on the default scene
    /// (256 x 256, 65536 walks, 2 cores): the single scattering 0.43 -> 0.10-0.16 s, image rel.
    /// RMSE 0.0450 -> 0.0444; its grid within 0.012 rel. RMSE and +0.06% of the plain one
    /// (compositor.rs `dome_spacing_interpolates_the_sky`).
    pub dome_spacing: u32,
    /// Random seed: walk w uses stream w of this seed, so the same seed gives the same S and
    /// consecutive frames share their paths.
    pub seed: u64,
}

impl Default for VplSettings {
    fn default() -> Self {
        VplSettings {
            walks: 4096,
            max_vertices: 4096,
            rr_depth: 4,
            walks_per_subset: 0,
            near_field: NearField::Auto,
            clamp_radius: 1.0,
            mean_free_paths: 0.25,
            phase_cone: 0.25,
            compensation_vertices: 4,
            compensation_depth: 2,
            compensation_walks: 256,
            gather_resolution: 16,
            output_resolution: 64,
            upsample: true,
            upsample_fit: UpsampleFit::Mean,
            near_refine: 0.0,
            near_upsample: NearUpsample::Plain,
            near_radius: 1.5,
            normalize_energy: true,
            transmittance: Transmittance::Map,
            map_resolution: 8,
            cluster_distance: 2.0,
            range_sigma: 0.15,
            spatial_sigma: 0.8,
            dome_directions: 32,
            dome_spacing: 2,
            seed: 1,
        }
    }
}

impl VplSettings {
    pub fn validate(&self) -> Result<()> {
        if !(1..=(1 << 24)).contains(&self.walks) {
            return Err(Error::scene("solver.walks", format!("must be in 1..=16777216, got {}", self.walks)));
        }
        if !(1..=(1 << 20)).contains(&self.max_vertices) {
            return Err(Error::scene("solver.max_vertices", format!("must be in 1..=1048576, got {}", self.max_vertices)));
        }
        if !(self.clamp_radius.is_finite() && self.clamp_radius > 0.0 && self.clamp_radius <= 16.0) {
            return Err(Error::scene("solver.clamp_radius", format!("must be in (0, 16], got {}", self.clamp_radius)));
        }
        if !(self.mean_free_paths.is_finite() && self.mean_free_paths >= 0.0) {
            return Err(Error::scene("solver.mean_free_paths", format!("must be >= 0, got {}", self.mean_free_paths)));
        }
        if !(self.phase_cone.is_finite() && (0.0..=16.0).contains(&self.phase_cone)) {
            return Err(Error::scene("solver.phase_cone", format!("must be in [0, 16], got {}", self.phase_cone)));
        }
        if !(1..=256).contains(&self.compensation_vertices) {
            return Err(Error::scene("solver.compensation_vertices", format!("must be in 1..=256, got {}", self.compensation_vertices)));
        }
        if !(1..=8).contains(&self.compensation_depth) {
            return Err(Error::scene("solver.compensation_depth", format!("must be in 1..=8, got {}", self.compensation_depth)));
        }
        if !(1..=(1 << 24)).contains(&self.compensation_walks) {
            return Err(Error::scene("solver.compensation_walks", format!("must be in 1..=16777216, got {}", self.compensation_walks)));
        }
        if !(2..=256).contains(&self.gather_resolution) {
            return Err(Error::scene("solver.gather_resolution", format!("must be in 2..=256, got {}", self.gather_resolution)));
        }
        if !(self.near_refine == 0.0 || (0.5..=4.0).contains(&self.near_refine)) {
            return Err(Error::scene("solver.near_refine", format!("must be 0 (off) or in [0.5, 4], got {}", self.near_refine)));
        }
        if !(self.near_radius.is_finite() && (0.5..=4.0).contains(&self.near_radius)) {
            return Err(Error::scene("solver.near_radius", format!("must be in [0.5, 4], got {}", self.near_radius)));
        }
        if !(self.cluster_distance == 0.0 || (0.5..=16.0).contains(&self.cluster_distance)) {
            return Err(Error::scene("solver.cluster_distance", format!("must be 0 (off) or in [0.5, 16], got {}", self.cluster_distance)));
        }
        if !(2..=64).contains(&self.map_resolution) {
            return Err(Error::scene("solver.map_resolution", format!("must be in 2..=64, got {}", self.map_resolution)));
        }
        self.upsampling().validate()?;
        if !(1..=8).contains(&self.dome_spacing) {
            return Err(Error::scene("solver.dome_spacing", format!("must be in 1..=8, got {}", self.dome_spacing)));
        }
        if !(1..=1024).contains(&self.dome_directions) {
            return Err(Error::scene("solver.dome_directions", format!("must be in 1..=1024, got {}", self.dome_directions)));
        }
        Ok(())
    }

    /// Number of interleaved walk subsets (at least 1, at most `walks`).
    pub fn subsets(&self) -> u32 {
        if self.walks_per_subset == 0 { 1 } else { (self.walks / self.walks_per_subset.max(1)).clamp(1, self.walks) }
    }
}
