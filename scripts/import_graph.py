#!/usr/bin/env python3
"""The file-level import graph of a Rust crate's `src/` (volscatter-core by default): which
file names which through `use crate::...`, `use super::...` or an inline `crate::a::b` path.

Test modules are left out (a file's text from its first `#[cfg(test)]` on, and files named
`*tests.rs` or under `tests/` or `testing/`): a test may use any layer. Prints the circles
(strongly connected components of more than one file) and the imports that break the floors
of docs/architecture.md (a solver naming another solver or the compositor, the registry named
by a solver, anything below `stages/` naming a layer above it). Exit status 1 when there is
any; `--quiet` prints only the verdict.

    python3 scripts/import_graph.py [--src core/src] [--quiet]
"""

import argparse
import re
import sys
from pathlib import Path

USE = re.compile(r"\b(?:pub(?:\([^)]*\))?\s+)?use\s+(\w+(?:::[\w{}, *:\n]+)?);", re.S)
INLINE = re.compile(r"(?<![\w:])(\w+(?:::\w+)+)")
SOLVERS = ("auto", "lpm", "network", "photon_grid", "pop", "reference", "vpl")


def is_test_file(rel: Path) -> bool:
    parts = rel.parts
    return rel.name.endswith("tests.rs") or "tests" in parts[:-1] or "testing" in parts[:-1] or rel.name == "testing.rs"


def module_of(rel: Path) -> list[str]:
    parts = list(rel.with_suffix("").parts)
    if parts[-1] in ("mod", "lib"):
        parts = parts[:-1]
    return parts


def resolve(files: dict, path: list[str]):
    """The longest prefix of `path` that is a module file."""
    for n in range(len(path), -1, -1):
        key = tuple(path[:n])
        if key in files:
            return files[key]
    return None


def expand(spec: str) -> list[str]:
    """`a::{b, c::{d}}` -> ["a::b", "a::c::d"] (one path per leaf)."""
    spec = re.sub(r"\s+", "", spec)
    depth, start = 0, None
    for i, ch in enumerate(spec):
        if ch == "{":
            if depth == 0:
                start = i
            depth += 1
        elif ch == "}":
            depth -= 1
            if depth == 0:
                prefix, inner, rest = spec[:start], spec[start + 1 : i], spec[i + 1 :]
                items, d, cur = [], 0, ""
                for c in inner:
                    if c == "," and d == 0:
                        items.append(cur)
                        cur = ""
                        continue
                    d += c == "{"
                    d -= c == "}"
                    cur += c
                items.append(cur)
                out = []
                for it in filter(None, items):
                    out += expand(prefix + it + rest)
                return out
    return [spec]


def absolute(module: list[str], path: str) -> list[str]:
    parts = [p for p in path.split("::") if p not in ("", "*", "self")]
    if not parts:
        return module
    if parts[0] == "crate":
        return parts[1:]
    if parts[0] != "super":
        # A path from a child module of this one (2018 paths); anything else is another crate.
        return module + parts
    base = list(module)
    while parts and parts[0] == "super":
        base = base[:-1]
        parts = parts[1:]
    return base + parts


def unit(name: str) -> str:
    """The unit a file belongs to: a top-level module of the crate, or under `solvers/` one
    solver's folder (or one file beside them). A folder's files naming each other (its mod.rs
    re-exporting its parts, the parts naming mod.rs's types) is the usual Rust shape, not a circle."""
    parts = Path(name).with_suffix("").parts
    if parts[0] in ("solvers", "pipeline") and len(parts) > 1:
        return parts[0] + "/" + parts[1]
    return parts[0]


def graph(src: Path):
    files = {}
    # Files declared as `#[cfg(test)] mod name;` are test modules too.
    test_only = set()
    for f in src.rglob("*.rs"):
        for m in re.finditer(r"#\[cfg\(test\)\]\s*(?:#\[path\s*=\s*\"([^\"]+)\"\]\s*)?(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", f.read_text()):
            base = f.parent if f.name in ("mod.rs", "lib.rs") else f.parent / f.stem
            test_only.add((f.parent / m.group(1)) if m.group(1) else base / (m.group(2) + ".rs"))
            test_only.add(base / m.group(2) / "mod.rs")
    for f in sorted(src.rglob("*.rs")):
        rel = f.relative_to(src)
        if not is_test_file(rel) and f not in test_only:
            files[tuple(module_of(rel))] = str(rel)
    edges = {name: set() for name in files.values()}
    for module, name in files.items():
        text = (src / name).read_text()
        block = re.search(r"#\[cfg\(test\)\]\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{", text)
        text = text[: block.start()] if block else text  # the test module, at the end of a file
        text = re.sub(r"#\[cfg\(test\)\][^\n]*\n[^\n]*\n", "", text)  # a test-only item of one line
        text = re.sub(r"//[^\n]*", "", text)
        paths = [p for m in USE.finditer(text) for p in expand(m.group(1))]
        paths += INLINE.findall(text)
        for p in paths:
            path = absolute(list(module), p)
            if not p.startswith(("crate", "super", "self")) and tuple(path[: len(module) + 1]) not in files:
                continue  # another crate's path, or a local item
            target = resolve(files, path)
            # lib.rs only declares modules and re-exports: `crate::Result` names error.rs.
            if target and target != name and target != "lib.rs":
                edges[name].add(target)
    return edges


def unit_graph(edges):
    units = {}
    for a, targets in edges.items():
        units.setdefault(unit(a), set())
        for b in targets:
            if unit(b) != unit(a):
                units[unit(a)].add(unit(b))
    for targets in list(units.values()):
        for b in targets:
            units.setdefault(b, set())
    return units


def circles(edges):
    """Tarjan's strongly connected components of more than one file."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in edges:
        if v not in index:
            visit(v)
    return out


def solver_of(name: str):
    parts = Path(name).parts
    if len(parts) >= 2 and parts[0] == "solvers" and Path(parts[1]).stem in SOLVERS:
        return Path(parts[1]).stem
    return None


FLOORS_ABOVE_STAGES = ("solvers", "compositor", "pipeline")


def floor_breaks(edges):
    out = []
    for a, targets in edges.items():
        for b in sorted(targets):
            sa, sb = solver_of(a), solver_of(b)
            if sa and sb and sa != sb and sa != "auto":
                out.append(f"{a} -> {b}: a solver names another solver")
            elif sa and sa != "auto" and (b.startswith("compositor") or b.startswith("pipeline")):
                out.append(f"{a} -> {b}: a solver names the compositor or the pipeline")
            elif sa and sa != "auto" and b == "solvers/registry.rs":
                out.append(f"{a} -> {b}: a solver names the registry (the list above it)")
            elif a.startswith("stages") and b.split("/")[0].split(".")[0] in FLOORS_ABOVE_STAGES:
                out.append(f"{a} -> {b}: stages/ names a floor above it")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--src", default=str(Path(__file__).resolve().parent.parent / "core" / "src"))
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    edges = graph(Path(args.src))
    found = circles(unit_graph(edges))
    breaks = floor_breaks(edges)
    if not args.quiet:
        for c in found:
            print(f"circle of {len(c)} modules: {' '.join(c)}")
        for b in breaks:
            print(b)
    n = sum(len(t) for t in edges.values())
    print(f"{len(edges)} files, {n} imports: {len(found)} circles ({sum(map(len, found))} modules), {len(breaks)} floor breaks")
    return 1 if found or breaks else 0


if __name__ == "__main__":
    sys.exit(main())
