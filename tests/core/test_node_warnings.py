"""Every warning a node gives reaches manifest.json, the report (metrics.json) and the summary, also
from the cache; a report's verdict becomes doubtful (issue 14, item 5)."""
from __future__ import annotations

import json
import sys

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tbha_graph.core import Array, Json, node
from tbha_graph.core.registry import Registry
from tbha_graph.core.runner import load_graph, run_graph


class WarnParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    n: int = Field(3, ge=1)
    warn: bool = True


#: Longer than a summary line: the summary must show it whole (wrapped), not cut
WARNING = ("the view is close to degenerate: small 2D errors move the camera a lot, so every 3D figure of this "
           "run may be off by tens of centimetres — give a known focal length or more joints to fix it")


@node("warntest.source", version=1, outputs={"x": Array("float64", ("n",))}, params=WarnParams)
def warn_source(ctx):
    """Gives a warning when asked."""
    if ctx.params.warn:
        ctx.warn(WARNING)
    return np.arange(ctx.params.n, dtype=np.float64)


@node("warntest.report", version=1, inputs={"x": Array("float", ("n",))}, outputs={"report": Json()})
def warn_report(ctx, x):
    """A report with a verdict."""
    return {"report": {"verdict": "ok", "verdict_reasons": [], "mean": float(x.mean())}}


PIPE = """
nodes:
  src: {type: warntest.source, params: {warn: WARN}}
  rep: {type: warntest.report, inputs: {x: src.x}}
outputs: {metrics.json: rep.report}
"""


def _reg():
    reg = Registry()
    reg.add_module(sys.modules[__name__], source="tests")
    return reg


def test_warnings_reach_manifest_and_report_also_from_cache(write, cache, tmp_path):
    p = write("w.yaml", PIPE.replace("WARN", "true"))
    for i in range(2):  # the second run takes both nodes from the cache
        out = tmp_path / f"o{i}"
        run = run_graph(load_graph(p, registry=_reg()), out_dir=out, cache=cache)
        assert {r.status for r in run.results.values()} == ({"ran"} if i == 0 else {"cached"})
        m = json.loads((out / "metrics.json").read_text())
        assert m["verdict"] == "doubtful" and m["warnings"] == [f"src: {WARNING}"]
        assert m["verdict_reasons"] == ["node 'src' gave a warning"] and m["mean"] == 1.0
        man = json.loads((out / "manifest.json").read_text())
        assert man["warnings"] == [{"node": "src", "message": WARNING}]
        assert man["nodes"]["src"]["warnings"] == [WARNING]
        assert run.output("metrics.json")["verdict"] == "doubtful"


def test_no_warning_keeps_the_verdict(write, cache, tmp_path):
    p = write("w.yaml", PIPE.replace("WARN", "false"))
    run_graph(load_graph(p, registry=_reg()), out_dir=tmp_path / "o", cache=cache)
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["verdict"] == "ok" and "warnings" not in m
    assert json.loads((tmp_path / "o" / "manifest.json").read_text())["warnings"] == []


def test_summary_is_short_shows_verdict_and_warnings_and_verbose_shows_all(write, tmp_path, monkeypatch, capsys):
    from tbha_graph.cli.run import main

    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    p = write("w.yaml", PIPE.replace("WARN", "true"))
    assert main([str(p), "--plugin", "test_node_warnings", "--out", str(tmp_path / "o"), "-q"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) <= 15
    text = "\n".join(out)
    assert "verdict: doubtful" in text and "src: the view is close to degenerate" in text
    assert f"src: {WARNING}" in " ".join(line.strip() for line in out)  # whole, however long
    assert "mean" not in text  # not a headline figure
    assert main([str(p), "--plugin", "test_node_warnings", "--out", str(tmp_path / "o"), "-q", "--verbose"]) == 0
    assert "mean" in capsys.readouterr().out
