"""Issue 40's cost guard: every solver at its default settings on a set of extreme but legal
scenes (at most 32^3 voxels, 128 x 128 pixels) against its median on ordinary scenes of the
same size. The aim: no scene beyond 10x its solver's median. Each run is capped (--limit,
default 120 s): a capped run shows as "> limit". Writes the "cost-guard" section of
BENCHMARKS.md.

    python3 scripts/bench_cost_guard.py [--solvers pop,lpm] [--limit 120] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import math
import random
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from benchlib import camera, log, publish, read_section, require_volscatter, table, usable_cores, utc_now

CAM = camera([0, -4.5, 0.4], 40, 128, 128)
SUN = {"type": "distant", "direction": [-0.5, 0.6, -0.62], "irradiance": 4.0}
SKY = {"type": "dome", "color": [0.1, 0.15, 0.3]}
PLUME = {"procedural": "plume", "dims": [32], "density_scale": 10.0, "albedo": 0.9, "g": 0.5}


def points(n: int, seed: int, spread: float, z: float | None = None, power: float = 40.0) -> list[dict]:
    rng = random.Random(seed)
    return [{"type": "point", "intensity": power / n,
             "position": [rng.uniform(-spread, spread), rng.uniform(-spread, spread),
                          z if z is not None else rng.uniform(-spread, spread)]} for _ in range(n)]


def mixed(n: int, seed: int) -> list[dict]:
    rng = random.Random(seed)
    out = []
    for k in range(n):
        p = [rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(1.2, 2.5)]
        kind = k % 3
        if kind == 0:
            out.append({"type": "point", "position": p, "intensity": 0.4})
        elif kind == 1:
            out.append({"type": "spot", "position": p, "direction": [0, 0, -1], "intensity": 0.4, "cone_half_angle_deg": 30})
        else:
            out.append({"type": "rect", "position": p, "normal": [0, 0, -1], "size": [0.3, 0.3], "radiance": 2.0})
    return out


#: ordinary scenes: each solver's median over these is its normal cost
ORDINARY = {
    "plume, sun + sky": {"medium": PLUME, "lights": [SUN, SKY]},
    "plume, point light beside it": {"medium": PLUME, "lights": [{"type": "point", "position": [1.2, -0.8, 0.6], "intensity": 30.0}]},
    "thin plume 16^3, sun": {"medium": {"procedural": "plume", "dims": [16], "density_scale": 2.0, "albedo": 0.8}, "lights": [SUN]},
}

#: the extreme but legal scenes of issue 40
EXTREME = {
    "10,000 point lights above": {"medium": PLUME, "lights": points(10_000, 1, 2.0, z=2.0)},
    "64 point lights inside the medium": {"medium": PLUME, "lights": points(64, 2, 0.5)},
    "100 mixed lights (point, spot, rect)": {"medium": PLUME, "lights": mixed(100, 3)},
    "dense white furnace 16^3 (albedo 1, white dome)": {"medium": {"procedural": "plume", "dims": [16], "density_scale": 40.0, "albedo": 1.0},
                                                  "lights": [{"type": "dome", "color": [1, 1, 1]}]},
    "dense small medium 16^3, sun": {"medium": {"procedural": "plume", "dims": [16], "density_scale": 80.0, "albedo": 0.95, "g": 0.8},
                                     "lights": [SUN, SKY]},
}


def run(bin_: Path, scene: dict, solver: str, tmp: Path, limit: float) -> tuple[float | None, str]:
    """Seconds of one render (None past the limit) and the notes it printed."""
    path = tmp / "scene.json"
    path.write_text(json.dumps({"format": 1, **scene, "camera": CAM, "solver": {"name": solver}}))
    cmd = [str(bin_), "render", str(path), "--solver", solver, "--device", "cpu", "--out", str(tmp / "o.exr"),
           "--report", str(tmp / "r.json")]
    t = time.monotonic()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired:
        return None, ""
    took = time.monotonic() - t
    notes = " ".join(line[6:] for line in p.stderr.splitlines() if line.startswith("note: ") and "software adapter" not in line)
    if p.returncode != 0:
        return took, "error: " + (p.stderr.strip().splitlines() or ["?"])[-1]
    # auto's pick, in short, from the report's `auto` object: what ran, at what predicted cost.
    pick = json.loads((tmp / "r.json").read_text()).get("auto")
    if pick:
        cost = f" (predicted error {pick['predicted_error']:.3f} in {pick['predicted_seconds']:.2f} s)" if pick.get("predicted_error") is not None else ""
        notes = "; ".join(x for x in [f"{pick['solver']} {pick['quality']}{cost}", notes] if x)
    return took, notes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--solvers", default="pop,vpl,photon-grid,network,lpm,auto")
    ap.add_argument("--limit", type=float, default=120.0, help="seconds before a run is stopped")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    bin_ = require_volscatter()
    solvers = [s for s in args.solvers.split(",") if s]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for solver in solvers:
            base = []
            for name, sc in ORDINARY.items():
                t, _ = run(bin_, sc, solver, tmp, args.limit)
                log(f"{solver:12s} {name:45s} {t}")
                base.append(t if t is not None else args.limit)
            median = statistics.median(base)
            for name, sc in EXTREME.items():
                t, notes = run(bin_, sc, solver, tmp, args.limit)
                log(f"{solver:12s} {name:45s} {t} {notes[:120]}")
                shown = f"> {args.limit:.0f}" if t is None else f"{t:.1f}"
                ratio = f"> {args.limit / median:.0f}" if t is None else f"{t / median:.1f}"
                flag = "" if t is not None and t <= 10 * median else " **over 10x**"
                rows.append(f"| `{solver}` | {name} | {median:.2f} | {shown} | {ratio}{flag} | {notes[:160] or '-'} |")
    # Rows of solvers not run this time are kept from the last run (--solvers reruns some).
    old = read_section("cost-guard") or ""
    kept = [r for r in old.splitlines() if r.startswith("| `") and r.split("`")[1] not in solvers]
    rows = kept + rows
    lines = [f"Each solver at its default settings, `--device cpu`, 128 x 128 pixels, media of at most 32^3 voxels; "
             f"written by `scripts/bench_cost_guard.py` on {utc_now()} ({usable_cores()} cores, shared). The median is "
             f"over the ordinary scenes ({', '.join(ORDINARY)}); the aim is every extreme scene within 10x of it. "
             f"Runs are stopped at {args.limit:.0f} s. Notes are what the solve said (the cost guard's among them)."]
    lines += [""] + table("| solver | extreme scene | median s | s | x median | notes |", rows)
    if not args.no_write:
        publish("cost-guard", ["## Cost guard on extreme scenes (issue 40; `scripts/bench_cost_guard.py`)", "", *lines])
    print("\n".join(lines))


if __name__ == "__main__":
    main()
