"""Scheduler and content-addressed cache: re-run only what changed, never serve stale or corrupt data."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from testnodes import CHAIN

from tbha_graph.core.errors import NodeFailed
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.core.types import hash_array

HERE = Path(__file__).parent


def statuses(run) -> dict[str, str]:
    return {k: r.status for k, r in run.results.items()}


def test_first_run_runs_all_second_is_cached(write, registry, cache, tmp_path):
    p = write("p.yaml", CHAIN)
    r1 = run_graph(load_graph(p, registry=registry), out_dir=tmp_path / "out", cache=cache)
    assert set(statuses(r1).values()) == {"ran"}
    assert np.allclose(r1.output("sum.npz"), 2 * 2 + 2 * 3)
    r2 = run_graph(load_graph(p, registry=registry), out_dir=tmp_path / "out", cache=cache)
    assert set(statuses(r2).values()) == {"cached"}
    assert np.array_equal(r2.output("sum.npz"), r1.output("sum.npz"))
    with np.load(tmp_path / "out" / "sum.npz", allow_pickle=False) as z:
        assert np.allclose(z["value"], 10.0)
    m = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert m["nodes"]["double"]["status"] == "cached" and m["nodes"]["double"]["params"]["factor"] == 2
    assert len(m["nodes"]["sum"]["cache_key"]) == 64 and "numpy" in m["packages"]


def test_param_change_reruns_only_node_and_descendants(write, registry, cache):
    p = write("p.yaml", CHAIN)
    run_graph(load_graph(p, registry=registry), cache=cache)
    r = run_graph(load_graph(p, registry=registry, sets={"triple.factor": 4}), cache=cache)
    assert statuses(r) == {"src": "cached", "double": "cached", "triple": "ran", "sum": "ran", "stats": "ran"}


def test_default_valued_param_written_explicitly_hits_cache(write, registry, cache):
    p = write("p.yaml", CHAIN)
    run_graph(load_graph(p, registry=registry), cache=cache)
    r = run_graph(load_graph(p, registry=registry, sets={"double.sleep": 0.0}), cache=cache)
    assert set(statuses(r).values()) == {"cached"}


def test_only_requested_outputs_run(write, registry, cache):
    p = write("p.yaml", CHAIN)
    r = run_graph(load_graph(p, registry=registry), outputs=["sum.npz"], cache=cache)
    assert set(r.results) == {"src", "double", "triple", "sum"}


def test_same_output_upstream_reuses_downstream(write, registry, cache):
    """Keys use content fingerprints: an upstream change that gives identical output re-runs nothing below."""
    p = write("p.yaml", """
        nodes:
          src: {type: test.source, params: {n: 3, value: 1.0}}
          s: {type: test.scale, inputs: {x: src.x}, params: {factor: 2}}
          t: {type: test.scale, inputs: {x: s.y}, params: {factor: 10}}
        outputs: {t.npz: t.y}
    """)
    run_graph(load_graph(p, registry=registry), cache=cache)
    r = run_graph(load_graph(p, registry=registry, sets={"src.value": 2.0, "s.factor": 1.0}), cache=cache)
    assert statuses(r) == {"src": "ran", "s": "ran", "t": "cached"}


def test_array_hash_includes_dtype_and_shape():
    a = np.zeros(4, dtype=np.float32)
    assert hash_array(a) != hash_array(a.view(np.int32))
    assert hash_array(a) != hash_array(a.reshape(2, 2))
    assert hash_array(np.arange(3.0)) == hash_array(np.arange(3.0))


def test_input_file_content_is_part_of_the_key(write, registry, cache, tmp_path):
    data = tmp_path / "nums.txt"
    data.write_text("1 2 3")
    p = write("p.yaml", """
        nodes:
          r: {type: test.read_numbers, params: {path: nums.txt}}
        outputs: {x.npz: r.x}
    """)
    r1 = run_graph(load_graph(p, registry=registry), cache=cache)
    assert list(r1.output("x.npz")) == [1, 2, 3]
    assert statuses(run_graph(load_graph(p, registry=registry), cache=cache)) == {"r": "cached"}
    data.write_text("4 5 6 7")
    r3 = run_graph(load_graph(p, registry=registry), cache=cache)
    assert statuses(r3) == {"r": "ran"} and list(r3.output("x.npz")) == [4, 5, 6, 7]


def test_editing_a_helper_module_invalidates(tmp_path, cache):
    """The code fingerprint covers helper modules of the same package, not just the node's own source."""
    pkg = tmp_path / "fppkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "helper.py").write_text("def f(x):\n    return x + 1\n")
    (pkg / "nodes.py").write_text(textwrap.dedent('''
        from tbha_graph.core import Array, node
        from . import helper

        @node("fp.inc", outputs={"y": Array("float")})
        def inc(ctx):
            "inc"
            import numpy as np
            return helper.f(np.zeros(2))
    '''))
    script = textwrap.dedent(f'''
        import sys; sys.path.insert(0, {str(tmp_path)!r})
        from tbha_graph.core import Pipeline, Cache
        from fppkg.nodes import inc
        p = Pipeline(); p.add("a", inc); p.output("y.npz", "a.y")
        r = p.run(cache=Cache({str(cache.root)!r}))
        print(r.results["a"].status, r.output("y.npz")[0])
    ''')
    run = lambda: subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split()
    assert run() == ["ran", "1.0"]
    assert run() == ["cached", "1.0"]
    (pkg / "helper.py").write_text("def f(x):\n    return x + 2\n")
    assert run() == ["ran", "2.0"]


def test_corrupt_entry_is_detected_and_recomputed(write, registry, cache, tmp_path):
    p = write("p.yaml", CHAIN)
    r1 = run_graph(load_graph(p, registry=registry), cache=cache)
    entry = Path(r1.results["sum"].entry_path)
    (entry / "y.npz").write_bytes(b"garbage")  # bit rot
    r2 = run_graph(load_graph(p, registry=registry), out_dir=tmp_path / "o", cache=cache)
    assert r2.results["sum"].status == "ran"
    assert np.allclose(r2.output("sum.npz"), 10.0)


def test_corrupt_meta_is_detected_and_recomputed(write, registry, cache):
    p = write("p.yaml", CHAIN)
    r1 = run_graph(load_graph(p, registry=registry), cache=cache)
    (Path(r1.results["double"].entry_path) / "meta.json").write_text("{not json")
    r2 = run_graph(load_graph(p, registry=registry), cache=cache)
    assert r2.results["double"].status == "ran"
    assert any("not valid JSON" in w for w in r2.results["double"].warnings)


KILL_SCRIPT = """
import os, signal, sys
sys.path.insert(0, {tests!r})
import testnodes
from tbha_graph.core import Cache, Pipeline
from tbha_graph.core.cache import Cache as C
def die(work):
    os.kill(os.getpid(), signal.SIGKILL)
C.after_payload_hook = staticmethod(die)
p = Pipeline()
p.add("src", testnodes.source, params={{"n": 3}})
p.output("x.npz", "src.x")
p.run(cache=Cache({root!r}))
"""


def test_killed_writer_leaves_no_entry(tmp_path, cache, registry):
    proc = subprocess.run([sys.executable, "-c", KILL_SCRIPT.format(tests=str(HERE), root=str(cache.root))], capture_output=True)
    assert proc.returncode == -signal.SIGKILL
    assert list(cache.iter_entries()) == []  # no half entry
    assert cache.info()["tmp_folders"] == 1  # only an unfinished tmp folder, removed by gc
    assert cache.gc(tmp_age_s=0)["removed_tmp"] == 1
    from tbha_graph.core import Pipeline
    import testnodes

    p = Pipeline(registry=registry)
    p.add("src", testnodes.source, params={"n": 3})
    p.output("x.npz", "src.x")
    assert p.run(cache=cache).results["src"].status == "ran"


CONCURRENT = """
import sys; sys.path.insert(0, {tests!r})
import testnodes
from tbha_graph.core import Cache, Pipeline
p = Pipeline()
p.add("src", testnodes.source, params={{"n": 200000}})
p.add("c", testnodes.counted, x="src.x", params={{"counter": {counter!r}, "factor": 3.0}})
p.output("y.npz", "c.y")
r = p.run(out_dir={out!r}, cache=Cache({root!r}))
print(float(r.output("y.npz").sum()))
"""


def test_two_runs_sharing_one_cache_at_once(tmp_path, cache):
    counter = tmp_path / "count.txt"
    procs = [
        subprocess.Popen([sys.executable, "-c", CONCURRENT.format(tests=str(HERE), counter=str(counter), out=str(tmp_path / f"o{i}"), root=str(cache.root))], stdout=subprocess.PIPE, text=True)
        for i in range(2)
    ]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert outs[0] == outs[1] == str(3.0 * 200000)
    assert len(list(cache.iter_entries())) == 2
    for i in range(2):
        with np.load(tmp_path / f"o{i}" / "y.npz", allow_pickle=False) as z:
            assert z["value"].shape == (200000,)


def test_failing_node_names_node_leaves_no_run_dir_and_resumes(write, registry, cache, tmp_path):
    p = write("p.yaml", """
        nodes:
          src: {type: test.source}
          s: {type: test.scale, inputs: {x: src.x}}
          f: {type: test.fail, inputs: {x: s.y}}
        outputs: {f.npz: f.y, s.npz: s.y}
    """)
    out = tmp_path / "out"
    with pytest.raises(NodeFailed) as ei:
        run_graph(load_graph(p, registry=registry), out_dir=out, cache=cache)
    assert ei.value.node == "f" and "frame 3" in ei.value.format() and "re-export" in ei.value.format()
    assert not out.exists() and not any(x.name.startswith(".out.partial") for x in tmp_path.iterdir())
    r = run_graph(load_graph(p, registry=registry), outputs=["s.npz"], cache=cache)
    assert statuses(r) == {"src": "cached", "s": "cached"}


def test_bug_in_node_keeps_traceback_for_author(write, registry, cache):
    p = write("p.yaml", """
        nodes:
          src: {type: test.source}
          f: {type: test.fail, inputs: {x: src.x}, params: {bug: true}}
        outputs: {f.npz: f.y}
    """)
    with pytest.raises(NodeFailed) as ei:
        run_graph(load_graph(p, registry=registry), cache=cache)
    assert "ZeroDivisionError" in ei.value.format() and "bug in node type 'test.fail'" in ei.value.format()


def test_wrong_output_shape_is_refused(write, registry, cache):
    p = write("p.yaml", "nodes:\n  b: {type: test.bad_output}\noutputs: {b.npz: b.y}\n")
    with pytest.raises(NodeFailed) as ei:
        run_graph(load_graph(p, registry=registry), cache=cache)
    assert "expected shape (*, 3), got (4, 2)" in ei.value.format()
    assert list(cache.iter_entries()) == []


def test_file_outputs_and_no_cache_mode(write, registry, tmp_path):
    p = write("p.yaml", """
        nodes:
          src: {type: test.source, params: {n: 2, value: 1.5}}
          t: {type: test.to_text, inputs: {x: src.x}}
        outputs: {x.txt: t.text}
    """)
    run_graph(load_graph(p, registry=registry), out_dir=tmp_path / "o", cache=False)
    assert (tmp_path / "o" / "x.txt").read_text() == "1.5 1.5"


def test_unwritable_output_dir_is_a_clear_error(write, registry, cache, tmp_path):
    from tbha_graph.core.errors import TbhaError

    blocker = tmp_path / "file"
    blocker.write_text("x")
    p = write("p.yaml", CHAIN)
    with pytest.raises(TbhaError) as ei:
        run_graph(load_graph(p, registry=registry), out_dir=blocker / "sub" / "out", cache=cache)
    assert "cannot create the output folder" in ei.value.format()


def test_cache_gc_by_size(write, registry, cache):
    run_graph(load_graph(write("p.yaml", CHAIN), registry=registry), cache=cache)
    assert cache.info()["entries"] == 5
    cache.gc(max_bytes=0)
    assert cache.info()["entries"] == 0
