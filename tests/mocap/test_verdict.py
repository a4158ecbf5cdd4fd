"""The capture's verdict (issue 14, item 5) and the short summary on a real pipeline (item 7)."""
from __future__ import annotations

import json
from pathlib import Path

from tbha_graph.mocap.evaluate.verdict import verdict

ROOT = Path(__file__).resolve().parents[2]
GOOD = {"frames": 210, "tracked_pct": 99.5, "reprojection_px_median": 0.6, "bone_length_cv_pct": 0.3, "inferred_pct": 0.5}


def test_good_take_is_ok():
    assert verdict(GOOD) == ("ok", [])


def test_doubtful_and_failed_with_reasons():
    v, reasons = verdict({**GOOD, "tracked_pct": 80.0})
    assert v == "doubtful" and reasons == ["tracking lost joints often: tracked_pct = 80 < 90"]
    v, reasons = verdict({**GOOD, "warnings": ["the focal length is ambiguous"]})
    assert v == "doubtful" and reasons == ["warning: the focal length is ambiguous"]
    v, reasons = verdict({**GOOD, "tracked_pct": 30.0, "reprojection_px_median": float("nan")})
    assert v == "failed" and len(reasons) == 2 and "reprojection_px_median = nan" in reasons[0]


def test_seed_pipeline_reports_the_calibration_warning_and_a_short_summary(tmp_path, monkeypatch, capsys):
    """The seed's coplanar Tsai warns that the sample's view is close to degenerate: today's main lost it."""
    from tbha_graph.cli.run import main

    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    out = tmp_path / "seed"
    assert main([str(ROOT / "pipelines" / "seed.yaml"), "--out", str(out), "--output", "metrics.json", "-q"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) <= 15, lines
    m = json.loads((out / "metrics.json").read_text())
    assert m["verdict"] == "doubtful"
    assert any(w.startswith("calibrate: the view is close to degenerate") for w in m["warnings"])
    assert "node 'calibrate' gave a warning" in m["verdict_reasons"]
    assert any("verdict: doubtful" in ln for ln in lines) and any("close to degenerate" in ln for ln in lines)
    documented = (ROOT / "docs" / "metrics.md").read_text()
    assert [k for k in m if f"`{k}`" not in documented] == []
    manifest = json.loads((out / "manifest.json").read_text())
    assert [w["node"] for w in manifest["warnings"]] == ["calibrate"]


def test_error_plot_legend_agrees_with_metrics_json(tmp_path):
    """errors.png's legend gives each 3D curve's mean over frames: metrics.json's mpjpe_mm / pa_mpjpe_mm."""
    from tbha_graph.core.runner import load_graph, run_graph
    from tbha_graph.mocap.viz.error_plot import legend_label

    g = load_graph(ROOT / "pipelines" / "seed.yaml", sets={"decode.stop": 60, "truth.stop": 60})
    run = run_graph(g, outputs=["metrics"], cache=False)
    metrics, errors = run.output("metrics.metrics"), run.output("metrics.errors")
    for key in ("mpjpe_mm", "pa_mpjpe_mm"):
        assert legend_label("x", errors[key], "mm") == f"x (mean over frames {metrics[key]:.3g} mm)"


def test_docs_list_every_key_of_the_default_pipelines_metrics():
    """Keys of the whole-take solver's report and the metrics node's own, as listed in its module doc."""
    import re

    import tbha_graph.mocap.evaluate.metrics as metrics_module

    documented = (ROOT / "docs" / "metrics.md").read_text()
    named = set(re.findall(r"``([a-z0-9_]+_(?:mm|px|pct|m_s2|m_s3|ms|deg|m|median|p95))``", metrics_module.__doc__.split("Output ``errors``")[0]))
    assert named and [k for k in sorted(named) if f"`{k}`" not in documented] == []
    for k in ("focal_px", "focal_sd_pct", "camera_height_m", "camera_distance_m", "camera_tilt_deg", "verdict", "warnings"):
        assert f"`{k}`" in documented
