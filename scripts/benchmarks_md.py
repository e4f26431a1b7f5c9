"""BENCHMARKS.md's section writer, kept under its old name: it lives in benchlib.py now.

    from benchlib import write_section
    write_section("reference", markdown_text)

replaces the text between `<!-- BEGIN reference -->` and `<!-- END reference -->` (markers kept),
or appends the section at the end of the file when it is missing, leaving every other section
untouched. The file is created with a title when it does not exist.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from benchlib import read_section, write_section

__all__ = ["read_section", "write_section"]

if __name__ == "__main__":  # tiny self-check: python scripts/benchmarks_md.py
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "B.md"
        write_section("a", "first", p)
        write_section("b", "second", p)
        write_section("a", "first, again\n| x |", p)
        t = p.read_text()
        assert t.count("<!-- BEGIN a -->") == 1 and "first, again" in t and "second" in t
        assert t.index("BEGIN a") < t.index("BEGIN b")
        assert read_section("a", p) == "first, again\n| x |" and read_section("c", p) is None
        print(t)
