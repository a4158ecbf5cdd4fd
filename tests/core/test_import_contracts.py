"""The layering contracts of pyproject.toml ([tool.importlinter]) hold: the core imports no mocap, mocap
stages import only downwards, no import cycles between the modules of a package. ``lint-imports``
(import-linter, in the ``test`` extra) checks them; this test runs it, so the suite fails on a violation."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _lint_imports(cwd: Path) -> subprocess.CompletedProcess:
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.fail("lint-imports is not installed: pip install -e '.[test]' (import-linter is in the test extra)")
    env = dict(os.environ, PYTHONPATH=str(cwd) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([exe, "--no-cache"], cwd=cwd, capture_output=True, text=True, env=env, timeout=300)


def test_lint_imports_keeps_every_contract():
    proc = _lint_imports(ROOT)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout and "4 kept" in proc.stdout


def test_an_upward_import_breaks_the_contracts(tmp_path):
    """The contracts are not vacuous: a copy of the package with calibrate importing reconstruct (an upward
    import, and a cycle) and the core importing mocap fails."""
    shutil.copytree(ROOT / "tbha_graph", tmp_path / "tbha_graph", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    with open(tmp_path / "tbha_graph" / "mocap" / "calibrate" / "known.py", "a") as f:
        f.write("\n\ndef _upward():\n    from ..reconstruct import solve_take  # noqa: F401\n")
    with open(tmp_path / "tbha_graph" / "core" / "show.py", "a") as f:
        f.write("\n\ndef _mocap():\n    import tbha_graph.mocap.skeleton  # noqa: F401\n")
    proc = _lint_imports(tmp_path)
    assert proc.returncode != 0
    out = proc.stdout
    assert "tbha_graph.mocap.calibrate is not allowed to import" in " ".join(out.split())
    assert "tbha_graph.core.show -> tbha_graph.mocap.skeleton" in out
    assert "No cycles are allowed in tbha_graph.mocap" in out
