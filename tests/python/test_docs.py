"""The README and docs/ as a newcomer follows them: every relative link resolves inside the
repository, the README stays a page, its numbers are the generated ones, and the commands and
snippets it gives work (the C build line is run as written; the Rust snippet is a compiled example).
"""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").rglob("*.md"))
sys.path.insert(0, str(ROOT / "scripts"))

# [text](target) and ![alt](target); the target ends at whitespace or ')'.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def prose_lines(text: str):
    """(line number, line) outside fenced code blocks."""
    fenced = False
    for n, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            yield n, line


def code_blocks(text: str, lang: str):
    return re.findall(rf"```{lang}\n(.*?)```", text, re.DOTALL)


@pytest.mark.parametrize("md", [README, *DOCS], ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve_inside_the_repository(md):
    bad = []
    for n, line in prose_lines(md.read_text(encoding="utf-8")):
        for target in LINK.findall(line):
            if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                continue  # a URL or an anchor of the same page
            path = (md.parent / target.split("#", 1)[0]).resolve()
            if ROOT.resolve() not in [path, *path.parents]:
                bad.append(f"{md.name}:{n}: {target} leaves the repository")
            elif not path.exists():
                bad.append(f"{md.name}:{n}: {target} does not exist")
    assert not bad, "\n".join(bad)


def test_readme_is_a_page():
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    # "about 150 lines": room for a generated table to grow a row or two.
    assert len(lines) <= 160, f"README.md has {len(lines)} lines: move detail to docs/"
    long = [f"{n}: {len(l)} characters" for n, l in prose_lines(text) if len(l) > 200]
    assert not long, "README.md lines over 200 characters outside code:\n" + "\n".join(long)
    # The two commands, exactly (CI runs the second).
    assert "cargo run --release -- render --out out/default.exr --png out/default.png" in text
    assert "\nbash scripts/test.sh " in text and "scripts/test.sh" in (ROOT / ".ci" / "run").read_text()
    assert "cargo install --path plugin" in text, "how to get `volscatter` on PATH"


def test_readme_numbers_are_the_generated_ones():
    import readme_tables
    stale = readme_tables.stale(README.read_text(encoding="utf-8"))
    assert not stale, f"README.md blocks {stale} differ from the data: run python3 scripts/readme_tables.py"


def test_readme_synopsis_lists_every_solver():
    b = Path(os.environ.get("VOLSCATTER_BIN", ROOT / "target" / "release" / "volscatter"))
    if not b.is_file():
        pytest.skip(f"volscatter binary not built at {b} (cargo build --release, or set VOLSCATTER_BIN)")
    names = [s["name"] for s in json.loads(subprocess.run([str(b), "solvers", "--json"], check=True,
                                                          capture_output=True, text=True).stdout)["solvers"]]
    m = re.search(r"--solver ([a-z|-]+)\]", README.read_text(encoding="utf-8"))
    assert m, "no `--solver a|b|...` in the README's synopsis"
    assert m.group(1).split("|") == names


def test_readme_rust_snippet_is_the_compiled_example():
    """The snippet is the body of core/examples/render_default.rs, which the workspace build compiles."""
    example = (ROOT / "core" / "examples" / "render_default.rs").read_text()
    (snippet,) = code_blocks(README.read_text(encoding="utf-8"), "rust")
    for line in snippet.strip().splitlines():
        assert line.strip() in example, f"README's Rust line not in the example: {line}"


def test_c_build_line_in_the_docs_links_and_runs(tmp_path):
    """docs/c-api.md's (and the README's) `cc` line, run as written from a folder laid out like the
    repository, with `target/` the cargo target folder this build used."""
    if shutil.which("cc") is None:
        pytest.skip("no C compiler `cc` on PATH")
    lib = Path(os.environ.get("VOLSCATTER_LIB", ROOT / "target" / "release" / "libvolscatter.so"))
    if not lib.is_file() or lib.parent.name != "release":
        pytest.skip(f"libvolscatter not built at {lib} (cargo build --release -p volscatter --lib)")
    lines = {}
    for md in (README, ROOT / "docs" / "c-api.md"):
        (cc,) = [l.split("  #")[0].strip() for b in code_blocks(md.read_text(encoding="utf-8"), "sh")
                 for l in b.splitlines() if l.startswith("cc ")]
        lines[md.name] = cc
    assert lines["README.md"] == lines["c-api.md"], lines
    for name in ("plugin", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / "target").symlink_to(lib.parent.parent)
    (tmp_path / "out").mkdir()
    env = dict(os.environ, PWD=str(tmp_path))
    r = subprocess.run(["bash", "-c", lines["README.md"]], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, f"{lines['README.md']}\n{r.stderr}"
    r = subprocess.run(["./smoke", "tests/c/smoke_scene.json", "out/"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and "smoke: ok" in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]


def test_benchmarks_are_laid_out_by_question():
    """BENCHMARKS.md reads by question (benchlib.QUESTIONS): every section sits under one, in
    the order the list gives, and none is left under "Other measurements"."""
    import benchlib

    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert benchlib.layout(text) == text, "BENCHMARKS.md is not in benchlib.layout's order: rewrite it with benchlib.layout"
    placed = {n for _, _, names in benchlib.QUESTIONS for n in names}
    unplaced = [n for n in re.findall(r"<!-- BEGIN ([A-Za-z0-9_.-]+) -->", text) if n not in placed]
    assert not unplaced, f"sections under no question (add them to benchlib.QUESTIONS): {unplaced}"


def test_a_section_written_into_another_file_leaves_the_file_as_it_is(tmp_path):
    """readme_tables.py writes README.md's blocks through write_section: only BENCHMARKS.md is
    rearranged by question, never the README around its blocks."""
    import benchlib
    readme = tmp_path / "README.md"
    readme.write_text("# A title\n\nProse.\n\n<!-- BEGIN readme-eevee -->\nold\n<!-- END readme-eevee -->\n\n## More\n")
    benchlib.write_section("readme-eevee", "new", readme)
    assert readme.read_text() == "# A title\n\nProse.\n\n<!-- BEGIN readme-eevee -->\nnew\n<!-- END readme-eevee -->\n\n## More\n"
