"""Shared writer for BENCHMARKS.md: each benchmark script owns one named section.

    from benchmarks_md import write_section
    write_section("reference", markdown_text)

replaces the text between `<!-- BEGIN reference -->` and `<!-- END reference -->` (markers kept),
or appends the section at the end of the file when it is missing, leaving every other section
untouched. The file is created with a title when it does not exist.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
TITLE = "# Benchmarks\n\nWritten by the scripts in `scripts/` (one section each); do not edit by hand.\n"


def write_section(name: str, markdown_text: str, path: str | os.PathLike = "BENCHMARKS.md") -> Path:
    """Replace (or append) section `name` of `path` with `markdown_text`. A relative `path` is
    taken relative to the repository root. Returns the path written."""
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise ValueError(f"section name must be [A-Za-z0-9_.-]+, got {name!r}")
    path = Path(path)
    if not path.is_absolute():
        path = REPO_ROOT / path
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    body = markdown_text.strip("\n")
    block = f"{begin}\n{body}\n{end}"
    text = path.read_text(encoding="utf-8") if path.exists() else TITLE
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.DOTALL)
    if pattern.search(text):
        text = pattern.sub(lambda _: block, text, count=1)
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    if not text.endswith("\n"):
        text += "\n"
    # Write atomically so that a script interrupted mid-write never truncates other sections.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".benchmarks.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)
    return path


if __name__ == "__main__":  # tiny self-check: python scripts/benchmarks_md.py
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "B.md"
        write_section("a", "first", p)
        write_section("b", "second", p)
        write_section("a", "first, again\n| x |", p)
        t = p.read_text()
        assert t.count("<!-- BEGIN a -->") == 1 and "first, again" in t and "second" in t
        assert t.index("BEGIN a") < t.index("BEGIN b")
        print(t)
