"""Issue 22: the USD reader on hostile stages. Every file of tests/corpus/usd is read, and seeded
mutations of them (numbers made NaN, infinite, huge, negative or strings; types swapped; lines
dropped or cut) are read too: each must give a scene or a VolscatterError, never another exception
(a traceback in the artist's console). Fixed seed, bounded cases (~10 s); VOLSCATTER_FUZZ_CASES=N
runs a longer campaign. A failing mutation is printed: add it to tests/corpus/usd.

Needs pxr (usd-core) only: stages are read, nothing is rendered."""
import os
import random
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "usd"))
pytest.importorskip("pxr", reason="pxr (usd-core) is not installed: pip install usd-core")

from volscatter import VolscatterError  # noqa: E402
from volscatter import stage as S  # noqa: E402

CORPUS = ROOT / "tests" / "corpus" / "usd"
SEEDS = sorted(CORPUS.glob("*.usda"))


def _read(path):
    try:
        S.read_stage(path).scene_json()
        return "ok"
    except VolscatterError as e:
        # Errors quote at most an excerpt: no megabyte messages.
        assert len(e.message) < 2000, e.message[:300]
        return "error"


@pytest.mark.parametrize("path", SEEDS, ids=[p.name for p in SEEDS])
def test_corpus_stage_reads_or_fails_cleanly(path):
    outcome = _read(path)
    # The base stage must read; each other corpus file reproduces a refusal of issue 22.
    assert outcome == ("ok" if path.name == "base.usda" else "error"), path.name


NUMBER = re.compile(r"(?<![\w.])-?\d+(\.\d+)?(e-?\d+)?(?![\w.])")
REPLACEMENTS = ["nan", "inf", "-inf", "1e39", "-1", "0", "3e38", "1e-45", '"text"', "@x.vdb@", "(1, 2)", "[]"]
TYPES = ["float", "double", "int", "string", "token", "asset", "color3f", "float3", "bool"]


def mutate(text: str, rng: random.Random) -> str:
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(5)
        if op <= 1:
            nums = list(NUMBER.finditer(text))
            if nums:
                m = rng.choice(nums)
                text = text[:m.start()] + rng.choice(REPLACEMENTS) + text[m.end():]
        elif op == 2:
            words = [m for m in re.finditer(r"\b(" + "|".join(TYPES) + r")\b", text)]
            if words:
                m = rng.choice(words)
                text = text[:m.start()] + rng.choice(TYPES) + text[m.end():]
        elif op == 3:
            lines = text.split("\n")
            del lines[rng.randrange(len(lines))]
            text = "\n".join(lines)
        else:
            text = text[:rng.randrange(len(text) + 1)]
    return text


def test_mutated_stages_read_or_fail_cleanly(tmp_path):
    cases = int(os.environ.get("VOLSCATTER_FUZZ_CASES", "150"))
    rng = random.Random(22)
    seeds = [p.read_text() for p in SEEDS]
    # The VDB path is relative to the corpus folder: keep it resolvable from tmp_path.
    (tmp_path / "vdb").mkdir()
    (tmp_path / "vdb" / "tiny_density.vdb").write_bytes((CORPUS.parent / "vdb" / "tiny_density.vdb").read_bytes())
    (tmp_path / "usd").mkdir()
    outcomes = {"ok": 0, "error": 0}
    for i in range(cases):
        text = mutate(rng.choice(seeds), rng)
        path = tmp_path / "usd" / f"case{i}.usda"
        path.write_text(text)
        try:
            outcomes[_read(path)] += 1
        except Exception as e:  # noqa: BLE001 - the finding
            pytest.fail(f"case {i}: {type(e).__name__}: {e}\n--- stage ---\n{text}")
    # Both outcomes occur: the mutations are neither all harmless nor all fatal.
    assert outcomes["ok"] > 0 and outcomes["error"] > 0, outcomes
