#!/usr/bin/env python3
"""Time per render before and after a change of the solve path (issue [1/8] "one path"): the
CLI's `render` of the embedded default scene and of the five benchmark scenes (bench/scenes/),
with each solver at its registry defaults, on the CPU, by two binaries taken in turns (before,
after, before, after, ...) so that both see the same load of a shared machine. The fastest of
`--repeats` runs of each counts (other jobs only ever add time). Writes the `one-path` section
of BENCHMARKS.md: seconds before and after and their ratio, measured in one run.

    python3 scripts/bench_one_path.py --before OLD/volscatter [--after target/release/volscatter]
        [--solvers pop,lpm] [--repeats 3] [--quick]
"""

import json
import tempfile
from pathlib import Path

import benchlib

SCENES = ("thin_smoke", "dense_cloud", "smoke_point", "overcast", "fire_smoke")


def render_seconds(binary: Path, scene: Path | None, solver: str, tmp: Path) -> float:
    """Wall-clock seconds of one `render` (scene loading and the EXR write included: what a user waits for)."""
    out, report = tmp / "out.exr", tmp / "report.json"
    _, seconds = benchlib.timed(benchlib.render, out, report, scene, solver=solver, device="cpu", binary=binary)
    return seconds


def main():
    ap = benchlib.quick_parser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", required=True, help="the CLI built from the commit before the change")
    ap.add_argument("--after", default=str(benchlib.volscatter_bin()), help="the CLI under test (default: target/release/volscatter)")
    ap.add_argument("--solvers", default="pop,lpm", help="comma-separated solvers, each at its defaults")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before-commit", default="", help="the commit the --before binary was built from (named in the table)")
    args = ap.parse_args()
    before, after = Path(args.before), Path(args.after)
    scenes = [("default", None)] + [(n, benchlib.REPO_ROOT / "bench" / "scenes" / n / "scene.json") for n in SCENES]
    if args.quick:
        scenes = scenes[:2]
    rows, ratios = [], []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for name, scene in scenes:
            for solver in args.solvers.split(","):
                times = {"before": [], "after": []}
                for _ in range(args.repeats):
                    for which, binary in (("before", before), ("after", after)):
                        times[which].append(render_seconds(binary, scene, solver, tmp))
                b, a = min(times["before"]), min(times["after"])
                ratios.append(a / b)
                benchlib.log(f"{name} {solver}: before {b:.3f} s, after {a:.3f} s, x{a / b:.3f}")
                rows.append(f"| {name} | {solver} | {b:.3f} | {a:.3f} | {a / b:.3f} |")
    geo = 1.0
    for r in ratios:
        geo *= r
    geo **= 1.0 / len(ratios)
    lines = [
        "## One path: time per render before and after",
        "",
        benchlib.written_line(f"python3 scripts/bench_one_path.py --before {before.name} --solvers {args.solvers} --repeats {args.repeats}", args.quick),
        f"`volscatter render` (CPU, each solver at its defaults, the scene's own image size), the fastest of {args.repeats} runs of each binary, "
        f"taken in turns. Before: the CLI built from {args.before_commit or 'the commit before the change'}; after: this tree's.",
        "",
        *benchlib.table("| scene | solver | before (s) | after (s) | after / before |", rows),
        "",
        f"Geometric mean of after / before: {geo:.3f}.",
    ]
    benchlib.publish("one-path", lines)
    print(json.dumps({"ratios": ratios, "geometric_mean": geo}))


if __name__ == "__main__":
    main()
