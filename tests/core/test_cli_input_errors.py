"""Silent wrong input and tracebacks become clear errors (issue 14, items 2 and 6)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from testnodes import CHAIN

from tbha_graph.cli import graph as graph_cli
from tbha_graph.cli import run as run_cli
from tbha_graph.core.errors import PipelineErrors
from tbha_graph.core.runner import load_graph

ROOT = Path(__file__).resolve().parents[2]
VARS = CHAIN.replace("description: a small chain", "description: a small chain\nvars: {n: 5}").replace("{n: 5, value", '{n: "${n}", value')


def test_misspelt_var_is_an_error_with_did_you_mean(write, registry):
    p = write("v.yaml", VARS)
    assert load_graph(p, vars={"n": 3}, registry=registry).nodes["src"].params.n == 3
    with pytest.raises(PipelineErrors) as e:
        load_graph(p, vars={"nn": 3}, registry=registry)
    assert "unknown variable 'nn'" in e.value.format() and "did you mean 'n'?" in e.value.format()


def test_a_var_used_but_not_declared_is_accepted(write, registry):
    p = write("u.yaml", CHAIN.replace("{n: 5, value", '{n: "${count}", value'))
    assert load_graph(p, vars={"count": 4}, registry=registry).nodes["src"].params.n == 4


def test_cli_misspelt_var_exits_2_before_running(write, tmp_path, capsys):
    p = write("v.yaml", VARS)
    assert run_cli.main([str(p), "--plugin", "testnodes", "--var", "nn=3", "--out", str(tmp_path / "o")]) == 2
    assert "did you mean 'n'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [["p.yaml", "--va", "video=x"], ["p.yaml", "--outp", "x"]])
def test_tbha_run_options_are_never_abbreviated(argv):
    with pytest.raises(SystemExit):
        run_cli.build_parser().parse_args(argv)


@pytest.mark.parametrize("argv", [["run", "p.yaml", "--va", "video=x"], ["show", "p.yaml", "--form", "dot"], ["batch", "p.yaml", "t/", "--var-n", "x"]])
def test_tbha_graph_options_are_never_abbreviated(argv):
    with pytest.raises(SystemExit):
        graph_cli.build_parser().parse_args(argv)


def test_output_subset_prints_a_summary_without_keyerror(write, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    p = write("c.yaml", CHAIN)
    assert run_cli.main([str(p), "--plugin", "testnodes", "--output", "sum.npz", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "sum.npz" in out
    assert sorted(x.name for x in (tmp_path / "o").iterdir()) == ["manifest.json", "sum.npz"]


@pytest.mark.parametrize("cmd", ["schema", "show pipelines/default.yaml", "nodes"])
def test_output_cut_short_by_head_is_quiet(cmd):
    r = subprocess.run(f"{sys.executable} -m tbha_graph.cli.graph {cmd} | head -c 1", shell=True, cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert "Traceback" not in r.stderr and "BrokenPipe" not in r.stderr, r.stderr


def test_deeply_nested_yaml_is_a_clear_error(write, registry, capsys):
    deep = write("deep.yaml", "nodes:\n  a: {type: test.source, params: {n: " + "[" * 3000 + "]" * 3000 + "}}\n")
    with pytest.raises(PipelineErrors, match="nested too deeply"):
        load_graph(deep, registry=registry)
    assert graph_cli.main(["validate", str(deep)]) == 2
    assert "nested too deeply" in capsys.readouterr().err


def test_deeply_nested_set_value_is_a_clear_error(write, registry, capsys):
    p = write("c.yaml", CHAIN)
    assert graph_cli.main(["validate", str(p), "--plugin", "testnodes", "--set", "src.n=" + "[" * 3000 + "]" * 3000]) == 2
    assert "nested too deeply" in capsys.readouterr().err


@pytest.mark.parametrize("source, tag", [
    ("given", "given"),
    ("room lines 698 px ± 0.7 %, refined by the take", "room lines"),
    ("lens file 700 px ± 0.5 %, refined by the take", "lens file"),
    ("estimated from the take", None),
])
def test_the_summary_says_where_the_focal_length_came_from(source, tag):
    """metrics.json's ``focal_source`` as ``reconstruct.solve_take`` writes it -> the summary's tag after focal_px."""
    assert run_cli.focal_origin(source) == tag
