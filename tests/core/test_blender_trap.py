"""The Blender trap (issue 14, item 11): nothing the project says or installs downgrades numpy below 2."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_no_extra_installs_bpy_with_its_numpy_pin():
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert "blender" in extras
    for name, reqs in extras.items():
        assert not [r for r in reqs if re.match(r"\s*bpy\b", r)], f"extra '{name}' would let pip downgrade numpy through bpy"
        assert not [r for r in reqs if re.search(r"numpy\s*<\s*2", r)], name


def test_every_bpy_install_command_uses_no_deps():
    texts = {p: p.read_text() for p in [ROOT / "README.md", *(ROOT / "docs").glob("*.md"), ROOT / "tests" / "integration" / "test_blender_import.py"]}
    commands = {p.name: re.findall(r"pip install[^`\n#]*bpy==[0-9.]*", t) for p, t in texts.items()}
    found = [c for cs in commands.values() for c in cs]
    assert found, "the docs give the command that installs bpy"
    assert [c for c in found if "--no-deps" not in c] == []
    assert 'BPY_INSTALL = "pip install --no-deps bpy==5.0.1"' in texts[ROOT / "tests" / "integration" / "test_blender_import.py"]
