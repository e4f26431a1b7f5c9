"""Benchmark of sessions (issue 14): 10 frames of a moving sun on the default scene (plume under
sun and sky, POP at its defaults) solved in one session against 10 one-off POP solves; writes
the "session" section of BENCHMARKS.md.

    python3 scripts/bench_session.py [--frames 10] [--repeats 3] [--degrees 4]

Runs core/examples/bench_session.rs (`cargo run --release`), which interleaves, frame by frame,
the one-off solve and the session's solve of the same scene, checks that they are bit-identical,
and reports each repeat's totals and per-phase sums. The table gives the median over repeats.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys

from benchlib import publish, run_cargo_example, today


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--degrees", type=float, default=4.0)
    args = ap.parse_args()
    out = run_cargo_example("volscatter-core", "bench_session",
                            ["--frames", str(args.frames), "--repeats", str(args.repeats), "--degrees", str(args.degrees)])
    sys.stderr.write(out.stderr)
    doc = json.loads(out.stdout.strip().splitlines()[-1])
    runs = doc["runs"]
    one = statistics.median(r["one_off_seconds"] for r in runs)
    sess = statistics.median(r["session_seconds"] for r in runs)
    phases = []
    for r in runs:
        for p in list(r["one_off_phases"]) + list(r["session_phases"]):
            if p not in phases:
                phases.append(p)

    def med(key, p):
        return statistics.median(r[key].get(p, 0.0) for r in runs)

    n = doc["frames"]
    lines = [
        "## Sessions: a moving sun, one session against one-off POP solves",
        "",
        f"`python3 scripts/bench_session.py` on {today()}, {platform.machine()},"
        f" {doc['threads']} worker threads (shared with other jobs: wall-clock, pessimistic). Default scene (64^3 plume,"
        f" sun + sky dome), POP at its defaults, CPU; {n} frames, the sun turned {doc['degrees_per_frame']:g} degrees"
        f" about the vertical per frame. Median of {len(runs)} repeats, each a new session, one-off and session solves"
        " interleaved frame by frame.",
        "",
        f"Every session frame bit-identical to its one-off solve: **{'yes' if doc['identical'] else 'NO'}**.",
        "",
        f"| {n} frames | total s | per frame s |",
        "|---|---|---|",
        f"| one-off solves | {one:.3f} | {one / n:.3f} |",
        f"| one session | {sess:.3f} | {sess / n:.3f} |",
        f"| saved | {one - sess:.3f} ({100 * (one - sess) / one:.0f}%) | {(one - sess) / n:.3f} |",
        "",
        f"Per phase, summed over the {n} frames (seconds; `pop medium key` is the session's fingerprint of the medium,"
        " which decides what may be reused):",
        "",
        "| phase | one-off | session | saved |",
        "|---|---|---|---|",
    ]
    for p in phases:
        a, b = med("one_off_phases", p), med("session_phases", p)
        lines.append(f"| {p} | {a:.3f} | {b:.3f} | {a - b:+.3f} |")
    lines += [
        "",
        "What a session reuses while only the sun moves (core/src/solvers/pop/reuse.rs): the density mip, the dome's",
        "importance map (an importance propagation from the camera) and the dome's ordinates (grid, sweep and",
        "propagation: `light grid`, `init`, `propagation`; `reused lights` is the cost of copying them in and out).",
        "All are keyed on the medium's voxels, transform and material, the camera (importance, ordinates) and the",
        "ordinate itself, so a changed medium or camera recomputes them. The sun's grid, the residuum (it gathers the",
        "sun's rest), merge and upsampling are solved again each frame. Kept lights are the CPU backend's; on the GPU",
        "only the mip and the importance are reused. Not tried: warm-starting the propagation from the previous",
        "frame's accumulation (its answer would differ from the one-off solve's).",
    ]
    publish("session", lines)


if __name__ == "__main__":
    main()
