"""The floors of docs/architecture.md hold in volscatter-core: no circle between its modules,
no solver naming another solver, the compositor, the pipeline or the registry, nothing in
stages/ naming a floor above it (scripts/import_graph.py reads the imports). And the checker
itself sees a circle when there is one, so that a clean verdict means something."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CHECKER = ROOT / "scripts" / "import_graph.py"


def run(src):
    return subprocess.run([sys.executable, str(CHECKER), "--src", str(src)], capture_output=True, text=True)


def test_core_has_no_circle_and_keeps_its_floors():
    r = run(ROOT / "core" / "src")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 circles" in r.stdout and "0 floor breaks" in r.stdout, r.stdout


def test_checker_sees_a_circle_and_a_solver_naming_another(tmp_path):
    src = tmp_path / "src"
    (src / "solvers" / "a").mkdir(parents=True)
    (src / "solvers" / "vpl").mkdir(parents=True)
    (src / "lib.rs").write_text("pub mod compositor;\npub mod solvers;\n")
    (src / "compositor.rs").write_text("use crate::solvers::ScatteringGrid;\n")
    (src / "solvers" / "mod.rs").write_text("pub mod pop;\npub mod vpl;\nuse crate::compositor::x;\npub struct ScatteringGrid;\n")
    (src / "solvers" / "pop.rs").write_text("pub fn mip() {}\n")
    (src / "solvers" / "vpl" / "mod.rs").write_text("use crate::solvers::pop::mip;\n")
    r = run(src)
    assert r.returncode == 1, r.stdout
    assert "circle of 2 modules: compositor solvers/mod" in r.stdout, r.stdout
    assert "solvers/vpl/mod.rs -> solvers/pop.rs: a solver names another solver" in r.stdout, r.stdout
