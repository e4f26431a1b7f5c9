"""POP on the dense cloud, and POP's time per phase against the volume's size (issue 15);
writes the "pop-cloud" section of BENCHMARKS.md.

    python3 scripts/bench_pop_cloud.py [--sizes 16x16x16,...] [--variants NAME,...]

(a) The dense cloud (core/src/solvers/testing/cloud.rs: optical depth over 30, albedo 0.99,
g 0.9, one sun) against its converged reference fixture (fixtures/cloud.json, own noise 2.2%
image, 4.2% grid), for POP's defaults and the settings docs/pop-dense-clouds.md measured:
image and grid relative RMSE, their mean ratios (flux), and the solve's wall time. Runs the
ignored test `pop_sweep` (core/src/solvers/pop/tests/sweep.rs) with POP_SET per variant.
(b) Time per phase against the volume's size: the ignored test `pop_cost_by_volume`
(core/src/solvers/pop/tests/cost.rs: a smoke-like blob 1 m across at each voxel count, POP at
its defaults = the hosts' Preview preset, warm second solve) for a sun, a sun and a uniform sky,
and a point light (Blender's default scene light).

Uses cargo nextest with the release profile ($CARGO_TARGET_DIR as set); timings are wall
times on whatever machine runs it (the table says which).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess

from benchlib import REPO_ROOT, log, nextest_ignored_cmd, publish, utc_now

# (name, POP_SET): the defaults, then the options docs/pop-dense-clouds.md measures.
VARIANTS = [
    ("defaults", ""),
    ("moment_anisotropy", "moment_anisotropy=true"),
    ("moment_anisotropy + vacuum_escape", "moment_anisotropy=true,vacuum_escape=true"),
    ("defaults, grid_resolution 16", "grid_resolution=16"),
    ("moment_anisotropy, grid_resolution 64", "moment_anisotropy=true,grid_resolution=64"),
]
SIZES = "16x16x16,22x22x40,32x32x32,64x64x64,128x128x128,256x256x256"
NUM = r"([0-9.eE+-]+)"


def nextest(test: str, env: dict) -> str:
    cmd = nextest_ignored_cmd(test)
    r = subprocess.run(cmd, cwd=REPO_ROOT, env={**os.environ, **env}, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
    return r.stdout + r.stderr


def cloud_rows(variants) -> list[str]:
    pat = re.compile(rf"^cloud\s+image {NUM} \(x{NUM}\) grid {NUM} \(x{NUM}\) {NUM}s", re.M)
    rows = []
    for name, pop_set in variants:
        log(f"cloud: {name}")
        m = pat.search(nextest("pop_sweep", {"POP_SET": pop_set, "POP_ONLY_CLOUD": "1"}))
        if not m:
            raise SystemExit(f"no cloud line for {name}")
        image, flux, grid, gmean, secs = (float(x) for x in m.groups())
        rows.append(f"| {name} | {image:.3f} | {flux:.3f} | {grid:.3f} | {gmean:.3f} | {secs:.2f} |")
    return rows


def cost_rows(sizes: str) -> list[str]:
    out = nextest("pop_cost_by_volume", {"POP_COST_SIZES": sizes})
    rows, case = [], None
    for line in out.splitlines():
        if line.endswith(":") and not line.startswith(" "):
            case = line[:-1]
            continue
        m = re.match(rf"^\s+(\S+)\s+total {NUM} s \| (.*?) \|", line)
        if m and case:
            phases = ", ".join(p.strip() for p in m.group(3).split(","))
            rows.append(f"| {case} | {m.group(1)} | {float(m.group(2)):.3f} | {phases} |")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default=SIZES)
    ap.add_argument("--variants", default="", help="comma-separated variant names (default: all)")
    args = ap.parse_args()
    variants = [v for v in VARIANTS if not args.variants or v[0] in args.variants.split(",")]
    cloud = cloud_rows(variants)
    cost = cost_rows(args.sizes)
    when = utc_now()
    md = [
        "## POP on the dense cloud, and cost against volume size (issue 15)",
        "",
        f"`scripts/bench_pop_cloud.py`, {when}, {platform.machine()} with {os.cpu_count()} CPUs (shared: timings are indicative).",
        "",
        "Dense cloud (testing/cloud.rs; fixture noise: image 2.2%, grid 4.2%); POP settings = defaults",
        "plus the named change. Image/grid: relative RMSE against the reference; flux and grid mean:",
        "POP / reference. Goal of issue 15: image <= 0.15, flux within 5%.",
        "",
        "| settings | image | flux | grid | grid mean | solve (s) |",
        "|---|---:|---:|---:|---:|---:|",
        *cloud,
        "",
        "Time per phase (seconds, warm second solve, POP defaults = the hosts' Preview preset) against the",
        "volume's voxel count: a blob 1 m across (pop/tests/cost.rs).",
        "",
        "| lights | volume | total (s) | phases (s) |",
        "|---|---|---:|---|",
        *cost,
    ]
    publish("pop-cloud", md)


if __name__ == "__main__":
    main()
