"""Cost of the compositor's AOVs, before and after they became opt-in (issue 14); writes the
"composite" section of BENCHMARKS.md.

    python3 scripts/bench_composite.py [--before PATH] [--repeats N] [--quick]

Times `volscatter render --solver pop --device cpu` (256 x 256, 2 x 2 subpixels) on two scenes:
(a) the default scene, thin smoke (the procedural plume, 64^3) under a sun and a sky;
(b) Blender's noise-cube smoke (shared/fixtures/blender_noise_cube, 40^3 VDB written by
Blender) under a point light and a dim sky, the case the issue measured.
For each build: POP's solve (the `pop *` phases), the whole composite, and its
single-scattering part (the `composite: single-scattering AOV` phase, which only the new build
reports; the old one always computed it). The new build runs with `--aov background` (the
default: no single-scattering grid) and `--aov all`; the old build (`--before`: main's CLI,
built separately, or the release binary of the commit the change started from, copied aside)
always made every AOV. Each timing is the median of `--repeats` runs.
The `single` and `multiple` layers of the new build are compared with the old build's (relative
RMSE over pixels and RGB): what the fewer dome directions cost in accuracy.

Uses the `volscatter` CLI ($VOLSCATTER_BIN, default target/release/volscatter), numpy and
Mitsuba's EXR reader (tests/mitsuba/mitsuba_scenes.read_exr_layers).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import (SHARED, log, phase_sum, quick_mark, read_exr_layers, rel_rmse, render as render_report, today,
                      volscatter_bin, write_scene, publish)

SMOKE_VDB = SHARED / "fixtures" / "blender_noise_cube" / "volumes" / "Volume.vdb"
SINGLE_PHASE = "composite: single-scattering AOV"


def smoke_scene(work: Path) -> Path:
    """Blender's noise cube (density 4, albedo 0.8, g 0.3: tests/python/blender_scenes.py's
    scatter/absorb material) lit by a point light where blender_scenes.point() puts it, under
    a dim uniform sky."""
    scene = {
        "format": 1,
        "medium": {"vdb": str(SMOKE_VDB), "density_scale": 4.0, "albedo": [0.8, 0.8, 0.8], "g": 0.3},
        "lights": [{"type": "point", "position": [2.0, -1.0, 2.0], "intensity": [16, 16, 16]},
                   {"type": "dome", "color": [0.02, 0.025, 0.03]}],
        "camera": {"position": [0, -6, 0.5], "look_at": [0, 0, 0], "fov_deg": 39.6, "width": 256, "height": 256},
        "solver": {"name": "pop"},
    }
    return write_scene(work / "smoke.json", scene)


def render(binary: Path, scene: Path | None, out: Path, aov: str | None) -> dict:
    rep = render_report(out, out.with_suffix(".json"), scene, solver="pop", device="cpu", binary=binary,
                        extra=[] if aov is None else ["--aov", aov], stdout=subprocess.DEVNULL)
    ph = rep["phases_seconds"]
    return {"solve": phase_sum(rep, lambda k: k.startswith("pop")), "composite": ph["composite"], "single": ph.get(SINGLE_PHASE)}


def median_runs(binary: Path, scene: Path | None, out: Path, aov: str | None, repeats: int) -> dict:
    runs = [render(binary, scene, out, aov) for _ in range(repeats)]
    med = lambda k: None if runs[0][k] is None else statistics.median(r[k] for r in runs)  # noqa: E731
    return {k: med(k) for k in runs[0]}


def fmt(x) -> str:
    return "—" if x is None else f"{x:.2f}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", type=Path, default=Path("/tmp/composite-before/bin/volscatter"),
                    help="main's volscatter CLI, built before the change")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one repeat (for trying the script, not for committing)")
    args = ap.parse_args()
    repeats = 1 if args.quick else args.repeats
    after = volscatter_bin()
    for b in (after, args.before):
        if not b.exists():
            sys.exit(f"{b} not found (build it, or set VOLSCATTER_BIN / --before)")
    rows = []
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        scenes = [("(a) plume, sun + sky (default scene)", None), ("(b) Blender noise-cube smoke, point + dim sky", smoke_scene(work))]
        for label, scene in scenes:
            log(label)
            before = median_runs(args.before, scene, work / "before.exr", None, repeats)
            lb = read_exr_layers(work / "before.exr")
            no_aov = median_runs(after, scene, work / "none.exr", "background", repeats)
            with_aov = median_runs(after, scene, work / "all.exr", "all", repeats)
            la = read_exr_layers(work / "all.exr")
            ln = read_exr_layers(work / "none.exr")
            row = {"scene": label, "before": before, "no_aov": no_aov, "with_aov": with_aov,
                   "single_rrmse": rel_rmse(la["single"], lb["single"]),
                   "multiple_rrmse": rel_rmse(la["multiple"], lb["multiple"]),
                   "rgb_rrmse": rel_rmse(ln["rgb"], lb["rgb"]),
                   "layers_default": sorted(k for k in ln if k != "rgb")}
            rows.append(row)
            log(json.dumps(row))

    lines = [
        "## Compositor AOVs (`scripts/bench_composite.py`)",
        "",
        f"`python3 scripts/bench_composite.py` on {today()}, {platform.machine()},"
        f" {os.cpu_count()} CPU threads (shared with other jobs: wall-clock, pessimistic), median of {repeats}"
        f"{quick_mark(args.quick)}.",
        "`volscatter render --solver pop --device cpu`, 256 x 256, 2 x 2 subpixels. *Before*: the CLI of main as the",
        "change started from (commit 027183e's release build, copied aside before the change), which always",
        "computed the single-scattering grid (48^3, 64 dome directions). *After*: `--aov background` (the default: no",
        "single-scattering grid, no S1 lookups in the march) and `--aov all` (48^3, at most 32 dome directions, fewer for",
        "a dim dome; shadow rays stepping at the grid's spacing). *AOV cost* = composite with the AOVs minus composite",
        "without them (the single-scattering grid plus its lookups in the march). POP solve: the after build's `pop *`",
        "phases. Seconds.",
        "",
        "| scene | POP solve | before: composite | after, no AOV: composite | after, `--aov all`: composite | of which single-scattering grid | AOV cost | AOV cost / solve | single rRMSE vs before | multiple rRMSE vs before |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        cost = r["with_aov"]["composite"] - r["no_aov"]["composite"]
        solve = r["with_aov"]["solve"]
        lines.append(
            f"| {r['scene']} | {fmt(solve)} | {fmt(r['before']['composite'])} | {fmt(r['no_aov']['composite'])} | "
            f"{fmt(r['with_aov']['composite'])} | {fmt(r['with_aov']['single'])} | {fmt(cost)} | {cost / solve:.2f} | "
            f"{r['single_rrmse']:.4f} | {r['multiple_rrmse']:.4f} |")
    lines += [
        "",
        "Without the AOVs the RGBA image is unchanged (relative RMSE against main's: "
        + ", ".join(f"{r['rgb_rrmse']:.1e}" for r in rows)
        + f"); the default EXR's layers: {', '.join(rows[0]['layers_default']) or 'none'}.",
        "The single and multiple layers differ from main's by the dome's quadrature: 32 instead of 64",
        "importance-sampled directions for a bright sky, proportionally fewer for a dim one (`stages::single_scattering::dome_directions_for`;",
        "the longer shadow-ray step adds 0.05%).",
    ]
    publish("composite", lines)


if __name__ == "__main__":
    main()
