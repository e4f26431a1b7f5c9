"""Adds up the counts of cargo-nextest's and pytest's closing lines into one line."""
import re
import sys

counts = {"passed": 0, "failed": 0, "skipped": 0}
for path in sys.argv[1:]:
    try:
        text = open(path, encoding="utf-8", errors="replace").read()
    except OSError:
        continue
    lines = [l for l in text.splitlines() if l.strip()]
    # nextest: "Summary [...] 40 tests run: 38 passed, 2 failed, 3 skipped"
    # pytest:  "12 passed, 3 skipped in 4.2s" (last line)
    for line in reversed(lines):
        if "Summary" in line or re.search(r"\d+ (passed|failed)", line):
            for n, what in re.findall(r"(\d+) (passed|failed|skipped|errors?)", line):
                key = "failed" if what.startswith("error") else what
                counts[key] += int(n)
            break
print(f"tests: {counts['passed']} passed, {counts['failed']} failed, {counts['skipped']} skipped")
