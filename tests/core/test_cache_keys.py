"""The cache key is pure (issue 15, item 1) and the cache keeps house (item 2).

Key: comments, docstrings and formatting of the code a node runs do not count; its constants, its
code and every project module it imports (also inside a function) do; params count as the node sees
them after presets resolve. Housekeeping: a hit marks the entry used (gc is least-recently-used), the
file-hash memo follows the cache folder, Any-typed model outputs reload, Dask recomputes a corrupt
upstream entry and leaves no temp folders.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from pydantic import BaseModel

import testnodes
from tbha_graph.core import AnyType, Cache, Pipeline, node
from tbha_graph.core.keys import canonical_params, module_closure, node_key, source_fingerprint
from tbha_graph.core.registry import Registry
from tbha_graph.core.runner import load_graph, run_graph

HELPER = '''\
"""Helper module."""
SCALE = 2.0


def f(x):
    """Multiply."""
    return x * SCALE
'''

NODES = '''\
from tbha_graph.core import Array, node
from . import helper


@node("kp.inc", outputs={"y": Array("float")})
def inc(ctx):
    "inc"
    import numpy as np
    from .late import OFFSET   # imported inside the function: counted too
    return helper.f(np.zeros(2)) + OFFSET
'''


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """A throw-away package ``kpkg`` (nodes, helper, late) on sys.path; returns a key function that
    fingerprints it as it is on disk now (no memo, nothing imported)."""
    d = tmp_path / "kpkg"
    d.mkdir()
    (d / "__init__.py").write_text("")
    (d / "helper.py").write_text(HELPER)
    (d / "late.py").write_text("OFFSET = 1.0\n")
    (d / "nodes.py").write_text(NODES)
    (d / "unrelated.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for m in [m for m in sys.modules if m == "kpkg" or m.startswith("kpkg.")]:
        del sys.modules[m]

    def key() -> dict[str, str]:
        return module_closure("kpkg.nodes")

    return d, key


def test_comments_docstrings_and_formatting_do_not_change_the_key(pkg):
    d, key = pkg
    before = key()
    assert set(before) == {"kpkg", "kpkg.nodes", "kpkg.helper", "kpkg.late"}  # not kpkg.unrelated
    (d / "helper.py").write_text(
        "# a comment\n" + HELPER.replace('"""Multiply."""', '"""Multiply x by the scale.\n\n    Longer text."""')
        .replace("return x * SCALE", "return (x *\n            SCALE)  # same code"))
    assert key() == before


def test_a_module_constant_changes_the_key(pkg):
    d, key = pkg
    before = key()
    (d / "helper.py").write_text(HELPER.replace("SCALE = 2.0", "SCALE = 3.0"))
    after = key()
    assert after["kpkg.helper"] != before["kpkg.helper"] and after["kpkg.nodes"] == before["kpkg.nodes"]


def test_a_module_imported_inside_a_function_counts(pkg):
    d, key = pkg
    before = key()
    (d / "late.py").write_text("OFFSET = 5.0\n")
    assert key()["kpkg.late"] != before["kpkg.late"]
    (d / "unrelated.py").write_text("X = 2\n")  # not imported by the node: no effect
    assert key()["kpkg.late"] == key()["kpkg.late"] and "kpkg.unrelated" not in key()


def test_the_whole_key_follows_the_code_in_fresh_processes(pkg, tmp_path):
    """End to end, through the scheduler and the persistent code memo: a comment is a cache hit, a
    changed constant in a function-level import re-runs with the new value."""
    d, _ = pkg
    cache = tmp_path / "cache"
    script = textwrap.dedent(f'''
        import sys; sys.path.insert(0, {str(d.parent)!r})
        from tbha_graph.core import Pipeline, Cache
        from kpkg.nodes import inc
        p = Pipeline(); p.add("a", inc); p.output("y.npz", "a.y")
        r = p.run(cache=Cache({str(cache)!r}))
        print(r.results["a"].status, r.output("y.npz")[0])
    ''')
    run = lambda: subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split()
    assert run() == ["ran", "1.0"]
    (d / "nodes.py").write_text("# edited\n" + NODES.replace('"inc"', '"""Increment (now documented)."""'))
    assert run() == ["cached", "1.0"]
    (d / "late.py").write_text("OFFSET = 4.0\n")
    assert run() == ["ran", "4.0"]
    assert json.loads((cache / "codehash.json").read_text())  # the parsed modules are memoised per cache folder


def test_source_fingerprint_ignores_docstrings_only():
    a = source_fingerprint('"""doc"""\nX = 1\ndef f():\n    "d"\n    return X\n')[0]
    assert a == source_fingerprint('X = 1  # c\n\n\ndef f():\n    return X\n')[0]
    assert a != source_fingerprint('X = 1\ndef f():\n    return X + 0\n')[0]
    assert a != source_fingerprint('X = "doc"\ndef f():\n    return X\n')[0]  # a string constant is not a docstring


def test_project_constants_of_mocap_nodes_are_in_their_closure():
    """``DEFAULT_BONE_LENGTHS`` (skeleton) and the SMPL kinematic tree are code the nodes run."""
    from tbha_graph.mocap.reconstruct import solve_take
    from tbha_graph.mocap.smpl import from_rotations

    closure = module_closure(solve_take.__name__)
    assert "tbha_graph.mocap.skeleton" in closure and "tbha_graph.core.types" in closure  # stores its outputs
    assert "tbha_graph.mocap.smpl.kintree" in module_closure(from_rotations.__name__)
    # the scheduler runs the node but does not shape its result: `if TYPE_CHECKING:` imports never run
    assert "tbha_graph.core.scheduler" not in closure and "tbha_graph.core.pipeline" not in closure


# ---------------------------------------------------------------------------------------------
# effective params: export.bvh's presets
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rot():
    from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh

    r = rotations16_from_bvh(Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh")
    return {**r, "local_quat": r["local_quat"][:30:10].copy(), "root_position": r["root_position"][:30:10].copy(),
            "fps": np.asarray(12.0)}


def _export(params: dict, rot, tmp_path: Path) -> tuple[str, bytes, bytes]:
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.export.bvh import export_bvh

    key = node_key(export_bvh, export_bvh.params.model_validate(params), {"rotations": "same input"})
    work = tmp_path / f"w{len(list(tmp_path.iterdir()))}"
    out = run_node(export_bvh, params, work_dir=work, rotations=rot)
    return key, out["bvh"].read_bytes(), out["sheet"].read_bytes()


@pytest.mark.parametrize("sheet", [False, True])
def test_export_preset_and_explicit_equivalent_keys_match_exactly_when_outputs_do(rot, tmp_path, sheet):
    y_up = _export({"preset": "y-up", "sheet": sheet}, rot, tmp_path)
    y_up_explicit_same = _export({"preset": "y-up", "scale": 100.0, "rotation_order": "ZXY", "sheet": sheet}, rot, tmp_path)
    native_equivalent = _export({"preset": "none", "scale": 100.0, "rotation_order": "ZXY", "sheet": sheet}, rot, tmp_path)
    y_up_metres = _export({"preset": "y-up", "scale": 1.0, "sheet": sheet}, rot, tmp_path)  # explicit scale wins
    native_default = _export({"preset": "none", "sheet": sheet}, rot, tmp_path)
    runs = [y_up, y_up_explicit_same, native_equivalent, y_up_metres, native_default]
    for a in runs:
        for b in runs:
            same_key = a[0] == b[0]
            same_out = a[1:] == b[1:]
            assert same_key == same_out, (a[0][:8], b[0][:8], same_out)
    assert y_up[0] == y_up_explicit_same[0] and y_up[0] != y_up_metres[0]
    # without the contact sheet the preset's name is written nowhere: y-up and its explicit equivalent
    # are the same file; with the sheet its title names the preset, so they differ
    assert (y_up[0] == native_equivalent[0]) is (not sheet)


def test_y_up_preset_and_default_scale_written_explicitly_are_different_keys():
    """Today's bug: model_dump gave {preset: y-up, scale: 1.0} for both, but only one writes metres."""
    from tbha_graph.mocap.export.bvh import export_bvh

    a = export_bvh.params.model_validate({"preset": "y-up"})
    b = export_bvh.params.model_validate({"preset": "y-up", "scale": 1.0})
    assert a.model_dump() == b.model_dump()
    assert canonical_params(a) != canonical_params(b)


# ---------------------------------------------------------------------------------------------
# housekeeping
# ---------------------------------------------------------------------------------------------
def _chain(n_nodes: int = 3, last_factor: float = 2) -> Pipeline:
    p = Pipeline("chain", registry=_registry())
    p.add("src", "test.source", params={"n": 4, "value": 1.0})
    for i in range(1, n_nodes):
        p.add(f"s{i}", "test.scale", x=f"{'src' if i == 1 else f's{i - 1}'}.{'x' if i == 1 else 'y'}", params={"factor": last_factor if i == n_nodes - 1 else 2})
    p.output("y.npz", f"s{n_nodes - 1}.y")
    return p


def _registry() -> Registry:
    reg = Registry()
    reg.add_module(testnodes, source="tests")
    return reg


def test_a_hit_touches_its_entry_so_gc_removes_the_least_recently_used(tmp_path):
    cache = Cache(tmp_path / "c")
    a = Pipeline(registry=_registry()).add("a", "test.source", params={"n": 3, "value": 1.0}).output("x.npz", "a.x")
    b = Pipeline(registry=_registry()).add("b", "test.source", params={"n": 3, "value": 2.0}).output("x.npz", "b.x")
    ea = Path(a.run(cache=cache).results["a"].entry_path)
    eb = Path(b.run(cache=cache).results["b"].entry_path)
    old = time.time() - 3600
    os.utime(ea / "meta.json", (old - 60, old - 60))  # a was created first ...
    os.utime(eb / "meta.json", (old, old))
    assert a.run(cache=cache).results["a"].status == "cached"  # ... but used last
    size_b = sum(f.stat().st_size for f in eb.iterdir())
    size_a = sum(f.stat().st_size for f in ea.iterdir())
    cache.gc(max_bytes=max(size_a, size_b))
    assert ea.is_dir() and not eb.exists()


def test_the_file_hash_memo_follows_the_cache_folder(tmp_path, write):
    data = tmp_path / "numbers.txt"
    data.write_text("1 2 3")
    p = write("p.yaml", f"""
        nodes:
          r: {{type: test.read_numbers, params: {{path: {str(data)!r}}}}}
        outputs: {{x.npz: r.x}}
    """)
    one, two = Cache(tmp_path / "one"), Cache(tmp_path / "two")
    run_graph(load_graph(p, registry=_registry()), cache=one)
    run_graph(load_graph(p, registry=_registry()), cache=two)
    for c in (one, two):
        memo = json.loads((c.root / "filehash.json").read_text())
        assert str(data.resolve()) in memo
    assert one.file_memo is not two.file_memo


class Reading(BaseModel):
    value: float
    label: str


@node("kp.any_model", outputs={"out": AnyType()})
def any_model(ctx):
    "Returns a pydantic model through an Any port."
    return Reading(value=1.5, label="x")


def test_any_typed_model_output_reloads_from_the_cache(tmp_path):
    cache = Cache(tmp_path / "c")
    p = Pipeline().add("m", any_model).output("m.json", "m.out")
    p.run(cache=cache)
    run = p.run(cache=cache)  # a hit: the value is loaded from the entry
    assert run.results["m"].status == "cached"
    got = run.output("m.json")
    assert isinstance(got, Reading) and got == Reading(value=1.5, label="x")


def test_dask_recomputes_a_corrupt_upstream_entry_and_removes_its_temp_dirs(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    from distributed import Client, LocalCluster

    from tbha_graph.core.executors.dask_executor import run_dask
    from tbha_graph.core.progress import Reporter

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))  # the workers' temp folders land here
    cache = Cache(tmp_path / "c")
    g = _chain(3).build()
    r1 = run_graph(g, cache=cache)
    (Path(r1.results["s1"].entry_path) / "y.npz").write_bytes(b"bit rot")
    g2 = _chain(3, last_factor=5).build()  # s2 must run, so it loads s1's corrupt value
    warned: list[str] = []
    rep = Reporter(quiet=True)
    rep.warn = warned.append
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, Client(cl) as client:
        client.run(lambda: sys.path.insert(0, str(Path(testnodes.__file__).parent)))
        results = run_dask(g2, ["s2"], cache, rep, client=client)
        leftovers = client.run(lambda: sorted(os.listdir(__import__("tempfile").gettempdir())))
    assert results["s1"].status == "ran" and results["s2"].status == "ran"
    from tbha_graph.core.scheduler import RunResult

    assert np.allclose(RunResult(g2, results, 0).output("s2.y"), 1.0 * 2 * 5)
    assert any("checksum" in w and "s1" in w for w in warned), warned
    assert not [f for fs in leftovers.values() for f in fs if f.startswith("tbha-dask-")]
