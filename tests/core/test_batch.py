"""Batches over many takes: one row per take, failures isolated, shared cache, local and Dask."""
from __future__ import annotations

import numpy as np
import pytest

from tbha_graph.core.batch import collect_takes, run_batch
from tbha_graph.core.cache import Cache

PIPE = """
vars: {video: none}
nodes:
  r: {type: test.read_numbers, params: {path: "${video}"}}
  m: {type: test.metrics, inputs: {x: r.x}}
outputs: {metrics.json: m.metrics, x.npz: r.x}
"""


@pytest.fixture
def takes_dir(tmp_path):
    d = tmp_path / "takes"
    d.mkdir()
    (d / "a.txt").write_text("1 2 3")
    (d / "b.txt").write_text("4 5")
    (d / "broken.txt").write_text("")  # the node refuses an empty file
    return d


def test_batch_local_rows_failures_and_incremental_rerun(tmp_path, takes_dir, write):
    p = write("p.yaml", PIPE)
    cache = Cache(tmp_path / "c")
    takes = collect_takes(str(takes_dir / "*.txt"))
    assert [t.name for t in takes] == ["a", "b", "broken"]
    rows = run_batch(p, takes, tmp_path / "out", cache=cache, plugins=("testnodes",))
    by = {r["take"]: r for r in rows}
    assert by["a"]["status"] == "ok" and by["a"]["mean"] == 2.0 and by["a"]["frames"] == 3
    assert by["broken"]["status"] == "failed" and "holds no numbers" in by["broken"]["error"]
    with np.load(tmp_path / "out" / "b" / "x.npz", allow_pickle=False) as z:
        assert list(z["value"]) == [4, 5]
    assert "| take | status | frames |" in (tmp_path / "out" / "summary.md").read_text()
    (takes_dir / "c.txt").write_text("9")
    rows2 = run_batch(p, collect_takes(str(takes_dir)), tmp_path / "out2", cache=cache, plugins=("testnodes",))
    by2 = {r["take"]: r for r in rows2}
    assert by2["a"]["ran"] == 0 and by2["b"]["ran"] == 0 and by2["c"]["ran"] == 2


def test_batch_yaml_list(tmp_path, takes_dir, write):
    lst = write("takes.yaml", "takes:\n  - takes/a.txt\n  - {name: second, path: takes/b.txt}\n")
    takes = collect_takes(str(lst))
    assert [t.name for t in takes] == ["a", "second"] and takes[1].path == str((takes_dir / "b.txt").resolve())


def test_batch_on_dask_local_cluster_equals_local(tmp_path, takes_dir, write):
    pytest.importorskip("distributed")
    p = write("p.yaml", PIPE)
    takes = collect_takes(str(takes_dir / "*.txt"))
    local = run_batch(p, takes, tmp_path / "l", cache=Cache(tmp_path / "c1"), plugins=("testnodes",))
    dask = run_batch(p, takes, tmp_path / "d", cache=Cache(tmp_path / "c2"), executor="dask", workers=2, plugins=("testnodes",))
    strip = lambda rows: [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]
    assert strip(local) == strip(dask)


BATCH_VARS = """
vars: {video: none, scale: 1.0}
nodes:
  r: {type: test.read_numbers, params: {path: "${video}"}}
  s: {type: test.scale, inputs: {x: r.x}, params: {factor: "${scale}"}}
  m: {type: test.metrics, inputs: {x: s.y}}
outputs: {metrics.json: m.metrics}
"""


def test_batch_takes_var_and_set_like_tbha_run(tmp_path, takes_dir, write, monkeypatch, capsys):
    """issue 14 item 10: --var/--set apply to every take; a take's own set: wins; misspellings are errors."""
    from tbha_graph.cli.graph import main

    p = write("pv.yaml", BATCH_VARS)
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    argv = ["batch", str(p), str(takes_dir / "[ab].txt"), "--plugin", "testnodes", "--out", str(tmp_path / "o")]
    assert main(argv + ["--var", "scale=10"]) == 0
    rows = {r["take"]: r for r in run_batch(p, collect_takes(str(takes_dir / "a.txt")), tmp_path / "o2", cache=Cache(tmp_path / "c"),
                                            plugins=("testnodes",), vars={"scale": 10.0})}
    assert rows["a"]["mean"] == 20.0
    assert "| a | ok |" in (tmp_path / "o" / "summary.md").read_text()
    import csv

    with open(tmp_path / "o" / "summary.csv") as f:
        means = {r["take"]: float(r["mean"]) for r in csv.DictReader(f)}
    assert means == {"a": 20.0, "b": 45.0}
    assert main(argv[:-1] + [str(tmp_path / "o3"), "--set", "s.factor=3"]) == 0
    with open(tmp_path / "o3" / "summary.csv") as f:
        assert {r["take"]: float(r["mean"]) for r in csv.DictReader(f)} == {"a": 6.0, "b": 13.5}
    capsys.readouterr()
    assert main(argv[:-1] + [str(tmp_path / "o4"), "--var", "sclae=3"]) == 2
    assert "did you mean 'scale'" in capsys.readouterr().err and not (tmp_path / "o4").exists()
    assert main(argv[:-1] + [str(tmp_path / "o5"), "--var", "video=x.txt"]) == 2
    assert "conflicts with the takes" in capsys.readouterr().err
