"""Adds up the counts of cargo-nextest's and pytest's closing lines into one line.

    test_summary.py LOG... [--rerun-of-skipped LOG]

A `--rerun-of-skipped` log holds tests that the first runs reported as skipped (the GPU tests,
run a second time when an adapter exists): they are counted once, by their outcome.
"""
import re
import sys


def counts_of(path):
    counts = {"passed": 0, "failed": 0, "skipped": 0}
    try:
        text = open(path, encoding="utf-8", errors="replace").read()
    except OSError:
        return counts
    lines = [l for l in text.splitlines() if l.strip()]
    # nextest: "Summary [...] 40 tests run: 38 passed, 2 failed, 3 skipped"
    # pytest:  "12 passed, 3 skipped in 4.2s" (last line)
    for line in reversed(lines):
        if "Summary" in line or re.search(r"\d+ (passed|failed)", line):
            for n, what in re.findall(r"(\d+) (passed|failed|skipped|errors?)", line):
                key = "failed" if what.startswith("error") else what
                counts[key] += int(n)
            break
    return counts


args = sys.argv[1:]
rerun = None
if "--rerun-of-skipped" in args:
    i = args.index("--rerun-of-skipped")
    rerun = args[i + 1]
    del args[i:i + 2]
total = {"passed": 0, "failed": 0, "skipped": 0}
for path in args:
    for k, v in counts_of(path).items():
        total[k] += v
if rerun:
    r = counts_of(rerun)
    total["passed"] += r["passed"]
    total["failed"] += r["failed"]
    total["skipped"] = max(0, total["skipped"] - r["passed"] - r["failed"])
print(f"tests: {total['passed']} passed, {total['failed']} failed, {total['skipped']} skipped")
