"""Benchmark of farm bakes (issue 39): a 24-frame `volscatter-usd bake` of a generated sequence
(Blender's 40^3 noise cube under a sun turning 5 degrees a frame and a sky dome, pop at its
defaults), in this process with and without the session's reuse inside a chunk, and on a local
Dask cluster of 1 and 2 worker processes; writes the "farm" section of BENCHMARKS.md.

    python3 scripts/bench_farm.py [--frames 24] [--chunk 12] [--repeats 3]

Needs the library (VOLSCATTER_LIB or target/release/libvolscatter.so), usd-core and, for the
Dask rows, dask.distributed. Per-frame cost is each frame's time from its manifest record (solve
plus VDB write plus hashing); wall time is the whole command, layer and cluster start included.
The runs are interleaved over the repeats (so a change in the machine's load hits every row
alike) and the table gives medians.
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
import time
from pathlib import Path

from benchlib import publish, table, today

ROOT = Path(__file__).resolve().parents[1]
NOISE = ROOT.parent / "shared" / "fixtures" / "blender_noise_cube" / "volumes" / "Volume.vdb"


def make_stage(folder: Path, frames: int) -> Path:
    from pxr import Gf, UsdGeom, UsdLux
    sys.path.insert(0, str(ROOT / "tests" / "python"))
    from usd_stages import smoke_stage
    st, path = smoke_stage(folder, NOISE, name="seq.usda", vdb_path="d.vdb", focal=None)
    sun = UsdLux.DistantLight.Define(st, "/World/Sun")
    sun.CreateIntensityAttr().Set(1.0)
    op = UsdGeom.Xformable(sun).AddRotateYOp()
    for k in range(1, frames + 1):
        op.Set(-60.0 + 5.0 * k, float(k))
    sky = UsdLux.DomeLight.Define(st, "/World/Sky")
    sky.CreateIntensityAttr().Set(0.3)
    sky.CreateColorAttr().Set(Gf.Vec3f(0.5, 0.7, 1.0))
    st.SetStartTimeCode(1)
    st.SetEndTimeCode(frames)
    st.Save()
    return path


def bake(stage: Path, out: Path, frames: int, extra: list) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "usd"))
    cmd = [sys.executable, "-m", "volscatter", "bake", str(stage), "--frames", f"1-{frames}", "--solver", "pop",
           "--out-layer", str(out), "-q", *extra]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    recs = [json.loads(p.read_text()) for p in (out.parent / f"{out.stem}.manifest").glob("*.json")]
    secs = {int(r["frame"]): r["seconds"] for r in recs}
    assert len(secs) == frames, secs
    return {"wall": wall, "secs": secs}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--chunk", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    n, c = args.frames, args.chunk
    lib = os.environ.setdefault("VOLSCATTER_LIB", str(ROOT / "target" / "release" / "libvolscatter.so"))
    if not Path(lib).exists():
        raise SystemExit(f"libvolscatter not built at {lib}")
    try:
        import distributed  # noqa: F401
        dask = True
    except ImportError:
        dask = False
    runs = [("in-process, one chunk of %d (session reuse)" % n, [], n),
            ("in-process, chunks of 1 (no reuse)", ["--chunk", "1"], 1),
            ("in-process, chunks of %d" % c, ["--chunk", str(c)], c)]
    if dask:
        runs += [("Dask, 1 local worker, chunks of %d" % c, ["--workers", "1", "--chunk", str(c)], c),
                 ("Dask, 2 local workers, chunks of %d" % c, ["--workers", "2", "--chunk", str(c)], c)]
    results = {i: [] for i in range(len(runs))}
    loads = []
    with tempfile.TemporaryDirectory() as d:
        stage = make_stage(Path(d) / "stage", n)
        for rep in range(args.repeats):
            for i, (label, extra, chunk) in enumerate(runs):
                sys.stderr.write(f"repeat {rep + 1}/{args.repeats}: {label} ...\n")
                loads.append(os.getloadavg()[0])
                results[i].append(bake(stage, Path(d) / f"run{rep}-{i}" / "scatter.usda", n, extra))
    rows = []
    for i, (label, extra, chunk) in enumerate(runs):
        med = statistics.median
        wall = med(r["wall"] for r in results[i])
        per = med(statistics.mean(r["secs"].values()) for r in results[i])
        first = med(statistics.mean(s for k, s in r["secs"].items() if (k - 1) % chunk == 0) for r in results[i])
        later = ([statistics.mean(s for k, s in r["secs"].items() if (k - 1) % chunk != 0) for r in results[i]]
                 if chunk > 1 else [])
        rows.append(f"| {label} | {wall:.1f} | {per:.2f} | {first:.2f} | {f'{med(later):.2f}' if later else '-'} |")
    lines = ["## Farm bakes: chunks, session reuse, local Dask workers (`scripts/bench_farm.py`)", "",
             f"`python3 scripts/bench_farm.py --frames {n} --chunk {c} --repeats {args.repeats}` on {today()}, "
             f"{platform.machine()}, {os.cpu_count()} cores shared with other jobs (load average "
             f"{min(loads):.1f}-{max(loads):.1f} during the runs: wall-clock, pessimistic; medians of "
             f"{args.repeats} interleaved repeats). {n} frames of Blender's 40^3 "
             "noise cube under a sun turning 5 degrees a frame and a sky dome, pop at its defaults, one VDB per "
             "frame. Per-frame seconds are the manifest's (solve, VDB write, sha256); the first frame of a chunk "
             "starts its session, later ones reuse what the sun's move left valid (the density mip, the dome's "
             "importance and ordinates). Each worker process uses every core, so 2 workers on this machine "
             "share them." + ("" if dask else " dask.distributed is not installed: no Dask rows."), ""]
    lines += table("| run | wall s | per frame s | first of a chunk s | later frames s |", rows)
    publish("farm", lines)


if __name__ == "__main__":
    main()
