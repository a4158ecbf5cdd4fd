"""CLI, studies, the Python API, plugins by entry points, the Dask executor and the layering rule."""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from testnodes import CHAIN

import testnodes
from tbha_graph.cli import graph as graph_cli
from tbha_graph.cli import run as run_cli
from tbha_graph.core import Pipeline
from tbha_graph.core.errors import PipelineErrors, RegistryError
from tbha_graph.core.registry import Registry
from tbha_graph.core.runner import load_graph, run_graph

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).parent


def cli(main, argv, capsys):
    code = main(argv + ["--plugin", "testnodes"]) if argv[0] not in ("cache", "schema") or argv[0] == "schema" else main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_tbha_run_writes_run_dir_and_summary(write, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    p = write("p.yaml", CHAIN)
    code, out, err = cli(run_cli.main, [str(p), "--out", str(tmp_path / "run"), "--verbose"], capsys)
    assert code == 0, err
    assert "ran" in err and "fps achieved" in out and "mean" in out and str(tmp_path / "run" / "sum.npz") in out
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["mean"] == 10.0
    code, out, err = cli(run_cli.main, [str(p), "--out", str(tmp_path / "run")], capsys)
    assert "0 node(s) ran, 5 from cache" in out


def test_tbha_run_user_error_has_no_traceback(write, tmp_path, capsys):
    p = write("p.yaml", "nodes:\n  a: {type: test.sorce}\n")
    code, out, err = cli(run_cli.main, [str(p)], capsys)
    assert code == 2 and "Traceback" not in err and "did you mean 'test.source'" in err and f"{p}:2" in err


def test_tbha_run_node_failure_says_how_to_resume(write, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    p = write("p.yaml", "nodes:\n  s: {type: test.source}\n  f: {type: test.fail, inputs: {x: s.x}}\noutputs: {f.npz: f.y}\n")
    code, out, err = cli(run_cli.main, [str(p), "--out", str(tmp_path / "run")], capsys)
    assert code == 1 and "node 'f'" in err and "run the same command again" in err and not (tmp_path / "run").exists()


def test_nodes_listing_and_detail(capsys):
    code, out, _ = cli(graph_cli.main, ["nodes"], capsys)
    assert code == 0 and "test.source" in out and "A constant array" in out
    code, out, _ = cli(graph_cli.main, ["nodes", "test.source"], capsys)
    assert "params:" in out and "default 1.0 [m]" in out and "number of samples" in out and "Array[float64, (n,)]" in out


def test_validate_and_show(write, tmp_path, capsys):
    p = write("p.yaml", CHAIN)
    code, out, _ = cli(graph_cli.main, ["validate", str(p)], capsys)
    assert code == 0 and "ok (5 nodes" in out
    code, out, _ = cli(graph_cli.main, ["show", str(p), "--format", "mermaid", "--png", str(tmp_path / "g.png")], capsys)
    assert out.startswith("flowchart LR") and "src -- x --> double" in out
    assert (tmp_path / "g.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, out, _ = cli(graph_cli.main, ["show", str(p), "--format", "dot"], capsys)
    assert '"src" -> "double"' in out


def test_schema_validates_pipelines(write, capsys):
    jsonschema = pytest.importorskip("jsonschema")
    code, out, _ = cli(graph_cli.main, ["schema"], capsys)
    schema = json.loads(out)
    import yaml

    good = yaml.safe_load(CHAIN)
    jsonschema.validate(good, schema)
    bad = yaml.safe_load(CHAIN)
    bad["nodes"]["src"]["params"]["valeu"] = 1
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_cache_cli(tmp_path, capsys, write, registry):
    from tbha_graph.core.cache import Cache

    c = Cache(tmp_path / "c")
    run_graph(load_graph(write("p.yaml", CHAIN), registry=registry), cache=c)
    code, out, _ = cli(graph_cli.main, ["cache", "info", "--cache-dir", str(c.root)], capsys)
    assert "entries: 5" in out
    cli(graph_cli.main, ["cache", "clear", "--cache-dir", str(c.root)], capsys)
    assert c.info()["entries"] == 0


def test_study_table_with_failing_variant(write, tmp_path, registry):
    from tbha_graph.core.cache import Cache
    from tbha_graph.core.study import run_study

    write("base.yaml", CHAIN)
    s = write("study.yaml", """
        base: base.yaml
        inputs:
          small: {set: {src.n: 2}}
          large: {set: {src.n: 8}}
        variants:
          base: {}
          bigger: {set: {double.factor: 10}}
          broken: {nodes: {double: {type: test.fail}}}
    """)
    c = Cache(tmp_path / "c")
    rows = run_study(s, tmp_path / "st", cache=c, registry=registry)
    by = {(r["variant"], r["input"]): r for r in rows}
    assert by[("base", "small")]["mean"] == 10.0 and by[("bigger", "large")]["mean"] == 26.0
    assert by[("base", "large")]["n"] == 8
    assert by[("broken", "small")]["status"] == "failed" and "node 'double'" in by[("broken", "small")]["error"]
    assert by[("bigger", "small")]["cached"] >= 2  # src and triple shared with the base variant
    md = (tmp_path / "st" / "results.md").read_text()
    assert "| variant | input | status |" in md and "broken" in md
    assert (tmp_path / "st" / "results.csv").read_text().startswith("variant,input,status")
    assert (tmp_path / "st" / "results.png").is_file()  # the figures charted (the test below)


def test_python_api_without_yaml(tmp_path):
    p = Pipeline("python")
    p.add("src", testnodes.source, params={"n": 3, "value": 2.0})
    p.add("s", testnodes.scale, x="src.x", params={"factor": 5})
    p.output("y.npz", "s.y")
    run = p.run(out_dir=tmp_path / "o", cache=False)
    assert np.allclose(run.output("y.npz"), 10.0)
    bad = Pipeline()
    bad.add("s", testnodes.scale, x="nothing.y")
    with pytest.raises(PipelineErrors) as ei:
        bad.build()
    assert "unknown node 'nothing'" in ei.value.format() and "test_cli_study_plugins.py" in ei.value.format()


def test_progress_reporting_goes_through_context(write, registry, capsys):
    from tbha_graph.core.progress import Reporter

    p = write("p.yaml", "nodes:\n  s: {type: test.source}\n  f: {type: test.frames, inputs: {x: s.x}}\noutputs: {f.npz: f.y}\n")
    run = run_graph(load_graph(p, registry=registry), cache=False, reporter=Reporter(bars=True))
    err = capsys.readouterr().err
    assert "f: samples" in err and "ran" in err
    assert np.allclose(run.output("f.npz"), 2.0)


def test_registry_conflict_names_both_packages_and_broken_plugin_does_not_block(tmp_path):
    import copy

    reg = Registry()
    first, second = copy.copy(testnodes.source), copy.copy(testnodes.source)
    first.source = second.source = ""
    reg.add(first, source="pkg-a")
    with pytest.raises(RegistryError) as ei:
        reg.add(second, source="pkg-b")
    assert "pkg-a" in ei.value.format() and "pkg-b" in ei.value.format()
    (tmp_path / "brokenpkg").mkdir()
    (tmp_path / "brokenpkg" / "__init__.py").write_text("")
    (tmp_path / "brokenpkg" / "bad.py").write_text("import does_not_exist\n")
    (tmp_path / "brokenpkg" / "good.py").write_text(
        "from tbha_graph.core import node, Json\n@node('ok.node', outputs={'x': Json()})\ndef f(ctx):\n    'ok'\n    return 1\n"
    )
    sys.path.insert(0, str(tmp_path))
    try:
        reg2 = Registry()
        reg2.add_module("brokenpkg", source="brokenpkg")
        assert "ok.node" in reg2 and any("does_not_exist" in str(f) and "IMPORT FAILED" in str(f) for f in reg2.failures)
    finally:
        sys.path.remove(str(tmp_path))


def test_example_plugin_installs_and_runs(tmp_path):
    """Install the example plugin (no deps) into a private target folder; entry points find it."""
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--target", str(target), str(ROOT / "plugins" / "tbha-example-plugin")],
        check=True,
        capture_output=True,
    )
    pipe = tmp_path / "p.yaml"
    pipe.write_text(
        "nodes:\n  src: {type: test.source3d}\n  avg: {type: example.moving_average, inputs: {x: src.x}, params: {window: 3}}\noutputs: {avg.npz: avg.y}\n"
    )
    (tmp_path / "src3d.py").write_text(
        "import numpy as np\nfrom tbha_graph.core import node, Array\n"
        "@node('test.source3d', outputs={'x': Array('float', (None, None, None))})\n"
        "def s(ctx):\n    'ramp'\n    return np.arange(10.0).reshape(10, 1, 1) * np.ones((1, 2, 3))\n"
    )
    import os

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(target), str(tmp_path)]), "TBHA_CACHE_DIR": str(tmp_path / "c")}
    out = subprocess.run([sys.executable, "-m", "tbha_graph.cli.graph", "nodes"], env=env, capture_output=True, text=True)
    assert "example.moving_average" in out.stdout
    r = subprocess.run([sys.executable, "-m", "tbha_graph.cli.run", str(pipe), "--out", str(tmp_path / "o"), "--plugin", "src3d"], env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    with np.load(tmp_path / "o" / "avg.npz", allow_pickle=False) as z:
        y = z["value"]
    assert y.shape == (10, 2, 3) and np.isclose(y[5, 0, 0], 5.0) and np.isclose(y[0, 0, 0], 0.5)


def test_core_does_not_import_mocap():
    """Layering: the framework core and CLI know nothing of motion capture."""
    offenders = []
    for folder in ("core", "cli"):
        for f in (ROOT / "tbha_graph" / folder).rglob("*.py"):
            tree = ast.parse(f.read_text())
            for n in ast.walk(tree):
                names = []
                if isinstance(n, ast.Import):
                    names = [a.name for a in n.names]
                elif isinstance(n, ast.ImportFrom):
                    names = [("." * n.level) + (n.module or "")]
                for name in names:
                    if "mocap" in name:
                        offenders.append(f"{f.relative_to(ROOT)}: {name}")
    assert offenders == []


def test_dask_executor_matches_local_and_runs_independent_nodes_in_parallel(write, tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client, LocalCluster

    from tbha_graph.core.cache import Cache
    from tbha_graph.core.executors.dask_executor import run_dask
    from tbha_graph.core.progress import QUIET

    reg = Registry()
    reg.add_module(testnodes, source="tests")
    p = write("p.yaml", """
        nodes:
          src: {type: test.source, params: {n: 6, value: 1.5}}
          a: {type: test.interval, inputs: {x: src.x}, params: {factor: 2, sleep: 1.5, log: LOG}}
          b: {type: test.interval, inputs: {x: src.x}, params: {factor: 3, sleep: 1.5, log: LOG}}
          sum: {type: test.add, inputs: {a: a.y, b: b.y}}
        outputs: {sum.npz: sum.y}
    """)
    log = tmp_path / "intervals.txt"
    p.write_text(p.read_text().replace("LOG", str(log)))
    g = load_graph(p, registry=reg)
    local = run_graph(g, cache=False).output("sum.npz")
    log.unlink()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, Client(cluster) as client:
        client.run(lambda: __import__("testnodes") and __import__("tbha_graph.core.scheduler"))  # warm workers
        results = run_dask(g, ["sum"], Cache(tmp_path / "c"), QUIET, client=client)
    assert {k: r.status for k, r in results.items()} == {"src": "ran", "a": "ran", "b": "ran", "sum": "ran"}
    from tbha_graph.core.scheduler import RunResult

    dask_sum = RunResult(g, results, 0.0).output("sum.npz")
    assert np.array_equal(dask_sum, local)
    # the two independent nodes ran at the same time, in two worker processes
    (s1, e1, p1), (s2, e2, p2) = [tuple(map(float, ln.split())) for ln in log.read_text().splitlines()]
    assert p1 != p2 and max(s1, s2) < min(e1, e2)


def test_study_chart_draws_each_figure_as_bars_in_proportion(tmp_path):
    """results.png: a panel per figure (the run's bookkeeping and text left out), a bar per variant and input whose
    length in the picture is its value (a bar twice as long for twice the figure), failed runs named not drawn; a
    study without a figure gets a picture that says so (no bars), never the earlier run's left in place."""
    import cv2

    from tbha_graph.core.study_chart import chart_bars, chart_columns, write_chart

    rows = [{"variant": "a", "input": "x", "status": "ok", "wall_s": 3.0, "ran": 4, "cached": 0, "mm": 10.0, "ok": True, "name": "t"},
            {"variant": "b", "input": "x", "status": "ok", "wall_s": 0.1, "ran": 1, "cached": 3, "mm": 20.0},
            {"variant": "c", "input": "x", "status": "failed", "wall_s": 0.1, "error": "boom"}]
    assert chart_columns(rows) == ["mm"] and chart_columns(rows, ["name", "mm", "missing"]) == ["mm"]
    assert chart_bars(rows, "mm") == (["a", "b", "c"], ["x"], {("a", "x"): 10.0, ("b", "x"): 20.0, ("c", "x"): "failed"})
    png = write_chart(rows, tmp_path / "st", title="two bars")
    img = cv2.imread(str(png))
    blue = np.all(np.abs(img.astype(int) - (180, 119, 31)) < 8, axis=-1)  # matplotlib's first colour, C0, in BGR
    ys = np.flatnonzero(blue.any(axis=1))
    bands = np.split(ys, np.flatnonzero(np.diff(ys) > 1) + 1)
    widths = [blue[b].sum(axis=1).max() for b in bands]
    assert len(bands) == 2 and widths[1] == pytest.approx(2 * widths[0], rel=0.03), widths
    empty = write_chart([rows[2]], tmp_path / "st", title="all failed")  # replaces the earlier picture, says why
    assert empty == png and not np.all(np.abs(cv2.imread(str(png)).astype(int) - (180, 119, 31)) < 8, axis=-1).any()
