"""The registry resolves node types lazily (issue 15, item 6): an index of type -> module, from the
packages' source, so a run imports only its own nodes; the index agrees with what importing registers."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from tbha_graph.core.errors import RegistryError
from tbha_graph.core.registry import Registry, scan_nodes


def test_the_scan_finds_exactly_what_importing_registers():
    """Every node of tbha_graph.mocap is declared the way the scan reads (``@node("stage.name"``), in
    the module the import attributes it to: the lazy index can be trusted."""
    eager = Registry()
    eager.add_module("tbha_graph.mocap", source="tbha-graph")
    assert not eager.failures, eager.failures
    scanned = scan_nodes("tbha_graph.mocap")
    assert {t: [s.module] for t, s in ((s.type, s) for s in eager.specs())} == scanned
    assert len(scanned) >= 40


RUN_ONE_PIPELINE = textwrap.dedent("""
    import json, sys, time
    t0 = time.perf_counter()
    from tbha_graph.core.registry import default_registry
    from tbha_graph.core.runner import load_graph
    g = load_graph(sys.argv[1], vars={"clip": sys.argv[2]})
    mods = sorted(m for m in sys.modules if m.startswith("tbha_graph.mocap"))
    print(json.dumps({"types": sorted({b.spec.type for b in g.nodes.values()}), "mocap_modules": mods,
                      "scipy_optimize": "scipy.optimize" in sys.modules, "matplotlib": "matplotlib" in sys.modules}))
""")


def test_a_run_imports_only_its_pipelines_nodes(tmp_path):
    pipe = tmp_path / "p.yaml"
    pipe.write_text(textwrap.dedent("""
        vars: {clip: none.bvh}
        nodes:
          load: {type: io.bvh_load, params: {path: "${clip}"}}
          smooth: {type: filter.butterworth, inputs: {motion: load.motion}}
        outputs: {m.npz: smooth.motion}
    """))
    from pathlib import Path

    clip = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
    out = subprocess.run([sys.executable, "-c", RUN_ONE_PIPELINE, str(pipe), str(clip)], capture_output=True, text=True, check=True)
    got = json.loads(out.stdout)
    assert got["types"] == ["filter.butterworth", "io.bvh_load"]
    mods = got["mocap_modules"]
    assert "tbha_graph.mocap.io.bvh_load" in mods and "tbha_graph.mocap.filter.butterworth" in mods
    # none of the other stages' node modules, nor the heavy libraries they use
    for other in ("segment", "track", "reconstruct", "calibrate", "viz", "synth", "retarget", "smpl", "evaluate"):
        assert not [m for m in mods if m.startswith(f"tbha_graph.mocap.{other}.")], (other, mods)
    assert len(mods) <= 25, mods  # 21 measured (the port types' value modules among them); every node module: 120
    assert not got["scipy_optimize"] and not got["matplotlib"]


def test_help_imports_no_framework():
    code = "import sys; from tbha_graph.cli import graph, run; graph.build_parser(); run.build_parser(); " \
           "print(sorted(m for m in ('numpy', 'pydantic', 'tbha_graph.core', 'networkx') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.fixture
def lazypkg(tmp_path, monkeypatch):
    d = tmp_path / "lazypkg"
    d.mkdir()
    (d / "__init__.py").write_text("")
    (d / "a.py").write_text(textwrap.dedent('''
        from tbha_graph.core import Json, node

        @node("lazy.one", outputs={"x": Json()})
        def one(ctx):
            "one"
            return 1
    '''))
    (d / "b.py").write_text(textwrap.dedent('''
        from tbha_graph.core import Json, node

        def _two(ctx):
            "two, declared without the decorator: not in the index"
            return 2

        two = node("lazy.two", outputs={"x": Json()})(_two)
    '''))
    (d / "broken.py").write_text("import does_not_exist\n\n@node('lazy.broken')\ndef f(ctx):\n    return 0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield d
    for m in [m for m in sys.modules if m.split(".")[0] == "lazypkg"]:
        del sys.modules[m]


def test_lazy_package_imports_a_module_when_its_type_is_used(lazypkg):
    reg = Registry()
    assert sorted(reg.add_lazy("lazypkg", source="lazy-dist")) == ["lazy.broken", "lazy.one"]
    assert "lazy.one" in reg and "lazypkg.a" not in sys.modules
    spec = reg.get("lazy.one")
    assert spec.source == "lazy-dist" and "lazypkg.a" in sys.modules and "lazypkg.b" not in sys.modules
    # a type the scan cannot see is still found: an unknown name imports everything first
    assert reg.get("lazy.two").type == "lazy.two"
    assert any("does_not_exist" in str(f) and "IMPORT FAILED" in str(f) for f in reg.failures)
    with pytest.raises(RegistryError, match="unknown node type 'lazy.three'.*did you mean"):
        reg.get("lazy.three")


def test_lazy_conflict_names_both_packages(lazypkg):
    import dataclasses

    import testnodes

    reg = Registry()
    reg.add_lazy("lazypkg", source="lazy-dist")
    clash = dataclasses.replace(testnodes.source, type="lazy.one", source="")
    with pytest.raises(RegistryError) as ei:
        reg.add(clash, source="other-dist")
    assert "lazy-dist" in ei.value.format() and "other-dist" in ei.value.format()
