"""The fixed costs every composited image pays: the compositor's exact single-scattering grid
(shadow rays from 64^3 points to the sun and 32 dome directions) and the composite (camera
rays through the medium and S). Renders the default scene with each solver that uses them,
with the build under test (VOLSCATTER_BIN) and, when VOLSCATTER_BIN_BEFORE names an older
build, with that one too, in one run, and writes the per-phase times and their ratios to
BENCHMARKS.md (section `fixed-costs`). The reference path tracer is the control: it uses
neither stage, so its time should not move.

    VOLSCATTER_BIN=target/release/volscatter VOLSCATTER_BIN_BEFORE=/tmp/volscatter.main \\
        nice -n 15 python3 scripts/bench_fixed_costs.py

Each render runs on the CPU (`--device cpu`), best of `--repeat` runs, the two builds taking
turns (the machine is shared: the minimum is the least disturbed). The images' mean RGB of the two builds are compared too:
the change is meant to move them by float rounding only.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
from pathlib import Path

from benchlib import log, phase_sum, render, today, volscatter_bin, write_section

# (solver, extra arguments): vpl at the walks of issue 16's profile; the reference at few
# samples (a control only).
SOLVERS = [
    ("vpl", ["--set", "walks=1024"]),
    ("pop", []),
    ("photon-grid", []),
    ("lpm", []),
    ("network", []),
    ("reference", ["--spp", "16"]),
]


def render_default(binary: str, solver: str, extra: list[str]) -> dict:
    """The report of one render of the default scene."""
    with tempfile.TemporaryDirectory() as d:
        return render(Path(d) / "o.exr", Path(d) / "r.json", solver=solver, device="cpu", extra=extra, binary=binary,
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def best_of(binaries: list[str], solver: str, extra: list[str], repeat: int) -> list[dict]:
    """Per binary, the fastest of `repeat` renders, the binaries taking turns (so that a busy
    spell on the shared machine slows both alike, not one build's every run)."""
    best: list[dict | None] = [None] * len(binaries)
    for _ in range(repeat):
        for k, binary in enumerate(binaries):
            r = render_default(binary, solver, extra)
            if best[k] is None or r["total_seconds"] < best[k]["total_seconds"]:
                best[k] = r
    return best


def phase(report: dict, word: str) -> float:
    """Sum of the phases whose name contains `word` (solvers name their single-scattering
    phase after themselves: `vpl single scattering`, `lpm single scattering`, ...)."""
    return phase_sum(report, lambda k: word in k)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="print the table only")
    args = ap.parse_args()
    after_bin = str(volscatter_bin())
    before_bin = os.environ.get("VOLSCATTER_BIN_BEFORE")
    rows = []
    for solver, extra in SOLVERS:
        runs = best_of([after_bin] + ([before_bin] if before_bin else []), solver, extra, args.repeat)
        after, before = runs[0], (runs[1] if before_bin else None)
        rows.append((solver, before, after))
        log(solver, "done")

    def cell(before, after, word):
        a = phase(after, word) if word else after["total_seconds"]
        if before is None:
            return f"{a:.2f}"
        b = phase(before, word) if word else before["total_seconds"]
        ratio = f"{b / a:.2f}x" if a > 0 else "-"
        return f"{b:.2f} -> {a:.2f} ({ratio})" if b > 0 or a > 0 else "-"

    lines = [
        "## Fixed costs: single-scattering grid and composite (`scripts/bench_fixed_costs.py`)",
        "",
        f"`python3 scripts/bench_fixed_costs.py` on {today()}. "
        "The default scene (256x256, the plume under sun and sky), CPU, 2 threads, best of "
        f"{args.repeat}; seconds {'before -> after (speed-up)' if before_bin else ''}. `single` is the "
        "solver's exact single-scattering phase (the compositor's grid: shadow rays to the sun "
        "and 32 dome directions), `composite` the camera march through the medium and S. Both "
        "march the density through one dense copy per grid / composite (medium/dense_march.rs), "
        "with index-space rays, floor by truncation and one exp for grey media; the sample "
        "points are unchanged, so images move by float rounding only (`mean RGB rel.` is the "
        "largest relative difference of the image's mean RGB between the builds). The "
        "reference is the control: it uses neither stage.",
        "",
        "| solver | single (s) | composite (s) | total (s) | mean RGB rel. |",
        "|---|---|---|---|---|",
    ]
    for solver, before, after in rows:
        if before is not None:
            rel = max(abs(a - b) / max(abs(b), 1e-12) for a, b in zip(after["image"]["mean_rgb"], before["image"]["mean_rgb"]))
            rel_s = f"{rel:.1e}"
        else:
            rel_s = "-"
        lines.append(f"| {solver} | {cell(before, after, 'single scattering')} | {cell(before, after, 'composite')} | {cell(before, after, None)} | {rel_s} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.no_write:
        write_section("fixed-costs", text)


if __name__ == "__main__":
    main()
