"""Every GPU-capable solver end to end, as a host runs it: `volscatter render` of the embedded
default scene (256 x 256, the README's first command) at the registry presets, with `--device gpu`
and with `--device cpu`. Writes the "solvers-gpu" section of BENCHMARKS.md.

    python3 scripts/bench_solvers_gpu.py [--presets preview,final] [--repeat 2]

Uses the `volscatter` CLI ($VOLSCATTER_BIN, default target/release/volscatter); numpy and an EXR
reader (Mitsuba, or the OpenEXR package; scripts/benchlib.py's `exr_rel_rmse`) for the GPU image against the CPU's. Times are the render
report's: *solve* = every phase but loading, compositing and writing; *composite* = the ray-marched
image (on the GPU with `--device gpu`); the fastest of `--repeat` runs (the first run of a process
also compiles the kernels: each run is a new process, as a host's first frame is). On a software
adapter (Mesa's lavapipe) the GPU columns say nothing of GPU speed; a session lent a real GPU reruns
this script (scripts/bench_device.sh does).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import (exr_rel_rmse as rel_rmse, gpu_info, is_software_adapter, phase_sum, render_cmd, require_volscatter,
                      solver_registry, today, write_section)

NOT_SOLVE = ("load scene", "composite", "write")


def render(work: Path, solver: str, settings: dict, device: str, tag: str) -> dict:
    out, rep = work / f"{tag}.exr", work / f"{tag}.json"
    cmd = render_cmd(out, rep, solver=solver, device=device, settings=settings, extra=["--aov", "none"])
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr}")
    doc = json.loads(rep.read_text())
    return {
        "solve": phase_sum(doc, lambda k: k not in NOT_SOLVE),
        "composite": doc["phases_seconds"].get("composite", 0.0),
        "total": doc["total_seconds"],
        "device": doc["device"],
        "exr": out,
    }


def best(work: Path, solver: str, settings: dict, device: str, tag: str, repeat: int) -> dict:
    runs = [render(work, solver, settings, device, f"{tag}_{i}") for i in range(repeat)]
    return min(runs, key=lambda r: r["total"])


def adapter() -> tuple[str, bool]:
    p = gpu_info()
    lines = [l for l in p.stdout.splitlines() if l.strip()]
    name = lines[0] if lines else "none"
    return name, is_software_adapter(p.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="preview,final")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    require_volscatter()
    name, software = adapter()
    if name == "none":
        sys.exit("no GPU adapter (volscatter gpu-info): nothing to measure")
    entries = solver_registry()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        for e in entries:
            if not e["gpu"]:
                continue
            for preset in args.presets.split(","):
                p = next((p for p in e["presets"] if p["name"] == preset), None)
                if p is None:
                    continue
                tag = f"{e['name']}_{preset}"
                cpu = best(work, e["name"], p["settings"], "cpu", tag + "_cpu", args.repeat)
                gpu = best(work, e["name"], p["settings"], "gpu", tag + "_gpu", args.repeat)
                row = {"solver": e["name"], "preset": preset, "cpu": cpu, "gpu": gpu, "agree": rel_rmse(gpu["exr"], cpu["exr"])}
                print(json.dumps({k: v for k, v in row.items() if k not in ("cpu", "gpu")}
                                 | {"cpu_total": cpu["total"], "gpu_total": gpu["total"], "gpu_device": gpu["device"]}), flush=True)
                rows.append(row)
    label = "lavapipe (software, for correctness only: NOT GPU speed)" if software else name
    lines = [
        "## Every solver on the GPU, end to end (`scripts/bench_solvers_gpu.py`)",
        "",
        f"{today()}, GPU adapter: {label}; CPU {platform.machine()}, {os.cpu_count()} logical CPUs.",
        "`volscatter render` of the embedded default scene (256 x 256) at each GPU-capable solver's presets, `--device gpu`",
        "against `--device cpu`, `--aov none`; seconds from the render report, the fastest of "
        f"{args.repeat} runs, each a new process (kernels compiled in every run, as on a host's first frame).",
        "*solve*: the solver's phases (what runs on the GPU differs by solver: see each solver's GPU section); *composite*:",
        "the ray-marched image; *total*: the whole render, scene loading and EXR writing included.",
        "*image vs CPU*: the GPU render's relative RMSE against the CPU's: float rounding, except for vpl (the GPU marches",
        "every connection, the CPU uses per-point depth maps) and photon-grid (the GPU traces its own random photons,",
        "statistically equal to the CPU's: shaders/src/photon_grid/tests.rs), where it is the preset's noise or the map's error.",
        "",
        "| solver | preset | solve CPU | solve GPU | composite CPU | composite GPU | total CPU | total GPU | speed-up (total) | image vs CPU | devices (solve, composite) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        c, g = r["cpu"], r["gpu"]
        dev = ", ".join(g["device"].get(k, "?").split(":")[0] for k in ("solve", "composite"))
        lines.append(f"| {r['solver']} | {r['preset']} | {c['solve']:.3f} | {g['solve']:.3f} | {c['composite']:.3f} | {g['composite']:.3f} "
                     f"| {c['total']:.3f} | {g['total']:.3f} | {c['total'] / g['total']:.1f}x | {r['agree']} | {dev} |")
    text = "\n".join(lines) + "\n"
    if not args.no_write:
        write_section("solvers-gpu", text)
    print(text)


if __name__ == "__main__":
    main()
