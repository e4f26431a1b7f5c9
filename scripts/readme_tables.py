#!/usr/bin/env python3
"""Writes README.md's generated blocks from the measurements behind BENCHMARKS.md, so that no
number in the README is typed by hand:

- `bench-solvers`: which solver for which scene (`bench_solvers.readme_table` of
  core/src/pipeline/auto/measurements.json, the data of BENCHMARKS.md *Solvers against Cycles*);
- `readme-eevee`: the picture's error numbers, from BENCHMARKS.md's `eevee` section
  (scripts/bench_eevee.py).

    python3 scripts/readme_tables.py           # rewrite the blocks in README.md
    python3 scripts/readme_tables.py --check   # exit 1 when README.md is not what this writes
"""

from __future__ import annotations

import argparse
import json
import re
import sys

import bench_solvers
from benchlib import REPO_ROOT, write_section

README = REPO_ROOT / "README.md"
BENCHMARKS = REPO_ROOT / "BENCHMARKS.md"
#: The renders of the eevee section's table, as the README's columns name them.
EEVEE_COLUMNS = {"EEVEE alone": "EEVEE alone", "EEVEE + volscatter `pop`": "EEVEE + volscatter (`pop`, Preview)",
                 "EEVEE + volscatter `reference`": "EEVEE + volscatter (`reference`)"}


def section(text: str, name: str) -> str:
    m = re.search(rf"<!-- BEGIN {re.escape(name)} -->(.*?)<!-- END {re.escape(name)} -->", text, re.DOTALL)
    if not m:
        raise SystemExit(f"no section `{name}` in BENCHMARKS.md")
    return m.group(1)


def eevee_table(benchmarks: str) -> str:
    """Error against Cycles per scene: EEVEE alone, and with volscatter's result."""
    errors: dict[str, dict[str, str]] = {}
    for line in section(benchmarks, "eevee").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[1] in EEVEE_COLUMNS:
            errors.setdefault(cells[0], {})[cells[1]] = cells[2]
    if not errors:
        raise SystemExit("BENCHMARKS.md `eevee` has no rows of the renders " + ", ".join(EEVEE_COLUMNS))
    lines = ["Relative RMSE against Cycles with many volume bounces ([BENCHMARKS.md](BENCHMARKS.md) *EEVEE*, "
             "`scripts/bench_eevee.py`):", "",
             "| scene | " + " | ".join(EEVEE_COLUMNS.values()) + " |", "|---|" + "---:|" * len(EEVEE_COLUMNS)]
    for scene, row in errors.items():
        lines.append(f"| {scene} | " + " | ".join(row.get(k, "-") for k in EEVEE_COLUMNS) + " |")
    return "\n".join(lines)


def blocks() -> dict[str, str]:
    meas = json.loads(bench_solvers.MEASUREMENTS.read_text())
    return {"bench-solvers": bench_solvers.readme_table(meas),
            "readme-eevee": eevee_table(BENCHMARKS.read_text(encoding="utf-8"))}


def stale(readme: str) -> list[str]:
    """The blocks whose text in `readme` differs from what this script writes."""
    out = []
    for name, body in blocks().items():
        m = re.search(rf"<!-- BEGIN {name} -->\n(.*?)\n<!-- END {name} -->", readme, re.DOTALL)
        if not m or m.group(1) != body.strip("\n"):
            out.append(name)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 when a block is stale")
    args = ap.parse_args()
    if args.check:
        bad = stale(README.read_text(encoding="utf-8"))
        if bad:
            print(f"README.md: stale blocks {', '.join(bad)} (run python3 scripts/readme_tables.py)", file=sys.stderr)
        return 1 if bad else 0
    for name, body in blocks().items():
        write_section(name, body, path=README)
    return 0


if __name__ == "__main__":
    sys.exit(main())
