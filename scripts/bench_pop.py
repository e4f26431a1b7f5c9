"""Benchmark of the `pop` solver against the `reference` path tracer; writes the "pop" section of
BENCHMARKS.md.

    python3 scripts/bench_pop.py [--quick]

Uses only the `volscatter` CLI ($VOLSCATTER_BIN, default target/release/volscatter) and the
standard library. For each scene (the embedded default scene: plume under sun and sky; the
paper's Fig. 12 cube with g = 0.7; the plume with g = 0.9, albedo 0.99):
1. `volscatter compare --solvers pop,reference@4,reference@16,reference@64,reference`: POP
   (solve + composite) and the reference at 4/16/64 paths per pixel, all against a reference
   baseline at BASE_SPP, with the scattering grids compared on a 16^3 frame.
2. Equal-error speed-up: the reference's error falls as c / sqrt(spp) (c fitted on the three
   low-spp renders, median of err * sqrt(spp)); the spp at which it equals POP's error, times
   the reference's measured seconds per spp, is the reference's time to POP's error. The
   baseline's own noise is c / sqrt(BASE_SPP), reported.
3. POP's time per phase at grid resolutions 16, 32 and 48 on the default scene.
`--quick` divides the sample counts by 16 (for trying the script, not for committing numbers).
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

from benchlib import (camera, quick_parser, sample_counts, compare, log, noise_cube_vdb, require_volscatter, runs_by_solver, scene_doc, write_raw_f32,
                      write_scene, publish, written_line)

SWEEP = [4, 16, 64]
LIGHT = {"type": "distant", "direction": [0.4, -0.5, -0.75], "irradiance": [3.0, 3.0, 3.0], "angle_deg": 0.0}


def cube_scene(workdir: Path, g: float) -> Path:
    """The paper's Fig. 12 cube: 1 m, sigma_s = 4 / m, albedo 1 (16^3 voxels of density 1)."""
    n = 16
    raw = write_raw_f32(workdir / "cube16.f32", [1.0] * n ** 3)
    voxel = 1.0 / n
    medium = {"raw": raw.name, "dims": [n, n, n], "origin": [-(n - 1) * 0.5 * voxel] * 3, "voxel_size": voxel,
              "density_scale": 4.0, "albedo": [1.0, 1.0, 1.0], "g": g}
    return write_scene(workdir / f"cube_g{g}.json", scene_doc(medium, [LIGHT], camera([0, -4, 0.3], 22.0)))


def plume_scene(workdir: Path) -> Path:
    medium = {"procedural": "plume", "dims": [32], "density_scale": 8.0, "albedo": [0.99, 0.99, 0.99], "g": 0.9}
    return write_scene(workdir / "plume_g09.json", scene_doc(medium, [LIGHT], camera([0, -6, 0.3], 25.0)))


def blender_vdb_scene(workdir: Path) -> Path:
    """The VDB Blender 5.0.1 wrote for shared/fixtures/blender_noise_cube (Volume Cube + Noise,
    40^3 voxels over [-1, 1]^3), as smoke: density scale 8, albedo 0.95, g 0.6."""
    medium = {"vdb": str(noise_cube_vdb()), "grid": "density", "density_scale": 8.0, "albedo": [0.95, 0.95, 0.95], "g": 0.6}
    return write_scene(workdir / "blender_vdb.json", scene_doc(medium, [LIGHT], camera([0, -6, 0.3], 30.0)))


def main() -> None:
    args = quick_parser().parse_args()
    base_spp, grid_spp = sample_counts(args.quick, 4096, 1024)
    require_volscatter()
    rows, phase_rows = [], []
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        scenes = [
            ("default scene (plume, sun + sky), 64x64", None, ["--width", "64", "--height", "64"]),
            ("cube sigma_s 4, albedo 1, g 0.7, 48x48", cube_scene(work, 0.7), []),
            ("plume g 0.9, albedo 0.99, 48x48", plume_scene(work), []),
            ("Blender-exported VDB (noise cube), g 0.6, albedo 0.95, 48x48", blender_vdb_scene(work), []),
        ]
        solvers = ",".join(["pop"] + [f"reference@{s}" for s in SWEEP] + ["reference"])
        for label, scene, extra in scenes:
            doc = compare(scene, work / "cmp.json", solvers,
                          extra + ["--set", f"reference.spp={base_spp}", "--grid-resolution", "16", "--grid-spp", str(grid_spp)])
            runs = runs_by_solver(doc)
            pop = runs["pop"]
            sweep = [(s, runs[f"reference@{s}"]) for s in SWEEP]
            c = statistics.median(r["scattered_relative_rmse"] * s ** 0.5 for s, r in sweep)
            sec_per_spp = sweep[-1][1]["image_seconds"] / SWEEP[-1]
            err = pop["scattered_relative_rmse"]
            spp_eq = (c / err) ** 2 if err > 0 else float("inf")
            t_eq = spp_eq * sec_per_spp
            rows.append({
                "scene": label,
                "pop_seconds": pop["image_seconds"],
                "pop_solve_seconds": pop["grid_seconds"],
                "pop_image_rmse": pop["image_relative_rmse"],
                "pop_scattered_rmse": err,
                "pop_grid_rmse": pop["grid_relative_rmse"],
                "reference_spp_at_pop_error": spp_eq,
                "reference_seconds_at_pop_error": t_eq,
                "speedup": t_eq / pop["image_seconds"],
                "baseline_noise": c / base_spp ** 0.5,
                "grid_mean_ratio": statistics.mean(pop["grid_mean"]) / max(statistics.mean(runs["reference"]["grid_mean"]), 1e-30),
            })
            log(rows[-1])
        for res in (16, 32, 48):
            doc = compare(None, work / "phases.json", "pop,reference@1",
                          ["--no-grid", "--width", "32", "--height", "32", "--set", f"pop.grid_resolution={res}"])
            pop = next(r for r in doc["runs"] if r["solver"] == "pop")
            phase_rows.append((res, pop["phases_seconds"], pop["grid_seconds"]))
            log(res, pop["phases_seconds"])

    lines = [
        "## pop (principal-ordinates propagation, distant lights + dome ordinates)",
        "",
        written_line("python3 scripts/bench_pop.py", args.quick),
        f"Baseline: `reference` at {base_spp} spp; grids compared on 16^3 points, reference grid at {grid_spp} paths per point.",
        "POP at its defaults (32 cells along the longest side per light, 16 dome ordinates at 16 with importance, isotropic residuum, residual 1e-3, output 128).",
        "Errors are relative RMSE against the baseline: *image* as rendered (incl. background), *scattered* = image minus",
        "background (the light the solvers compute), *grid* = scattering grid S. *Reference at POP's error*: spp where the",
        "reference's own error c/sqrt(spp) (fitted at 4/16/64 spp) equals POP's scattered error, times its seconds per spp.",
        "",
        "| scene | POP s (solve + composite) | POP solve s | image rRMSE | scattered rRMSE | grid rRMSE | grid mean POP/ref | reference spp at POP's error | reference s at POP's error | speed-up | baseline noise |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['pop_seconds']:.2f} | {r['pop_solve_seconds']:.2f} | {r['pop_image_rmse']:.3f} | {r['pop_scattered_rmse']:.3f} | "
            f"{r['pop_grid_rmse']:.3f} | {r['grid_mean_ratio']:.2f} | {r['reference_spp_at_pop_error']:.1f} | {r['reference_seconds_at_pop_error']:.2f} | {r['speedup']:.2f}x | {r['baseline_noise']:.3f} |"
        )
    phases = ["pop mip", "pop light grid", "pop init", "pop propagation", "pop merge", "pop upsample", "composite"]
    lines += [
        "",
        "POP time per phase (seconds, wall) on the default scene (sun + 16 dome ordinates), 32x32 image:",
        "",
        "| grid resolution | " + " | ".join(p.replace("pop ", "") for p in phases) + " | solve total |",
        "|---|" + "---|" * (len(phases) + 1),
    ]
    for res, ph, total in phase_rows:
        lines.append(f"| {res} | " + " | ".join(f"{ph.get(p, 0.0):.3f}" for p in phases) + f" | {total:.3f} |")
    met = [r for r in rows if r["pop_scattered_rmse"] < 0.10 and r["speedup"] > 50]
    errs = [r["pop_scattered_rmse"] for r in rows]
    speed = [r["speedup"] for r in rows]
    lines += [
        "",
        f"Against the issue's aim (under 10% error at over 50x the reference's speed at that error): met on {len(met)} of"
        f" {len(rows)} scenes. POP's scattered-light error is {min(errs):.2f}-{max(errs):.2f} and its speed-up at equal error"
        f" {min(speed):.2f}x-{max(speed):.2f}x here. Why: POP is biased (one HG lobe about the light per cell cannot hold",
        "light that turned far from the light and kept its new direction, which is what a camera at 60-90 degrees from the",
        "light sees in forward-scattering media; see the tests), so the reference reaches POP's error after tens to hundreds",
        "of samples per pixel, which on these small images costs well under a second; POP's cost, dominated by up to 400",
        "propagation iterations on the CPU, does not shrink with the image (the reference's grows with the pixel count).",
        "The grid error of the default scene is larger than its image error: POP overestimates S deep inside the dense plume",
        "(mean ratio above), where the camera does not see (optically thick); the image error counts what is visible.",
        "Energy conservation and the per-case errors on the test scenes: core/src/solvers/pop/tests.rs.",
    ]
    publish("pop", lines)


if __name__ == "__main__":
    main()
