"""Every bundled study runs every variant (issue 14, item 8), in a fast setting: a shorter take."""
from __future__ import annotations

from pathlib import Path

import pytest

from tbha_graph.core.cache import Cache
from tbha_graph.core.study import read_study, run_study

ROOT = Path(__file__).resolve().parents[2]
STUDIES = sorted((ROOT / "studies").glob("*.yaml"))
#: per study, the --set that makes it quick; the default cuts the sample to its first 2 s (T-pose included)
FAST = {"filters.yaml": {"lead_in.duration": 0.5}}
DEFAULT_FAST = {"decode.stop": 60, "truth.stop": 60}


@pytest.mark.parametrize("study", STUDIES, ids=lambda p: p.stem)
def test_every_variant_of_every_bundled_study_runs(study, tmp_path):
    rows = run_study(study, tmp_path / "out", cache=Cache(tmp_path / "cache"), sets=FAST.get(study.name, DEFAULT_FAST))
    spec = read_study(study)
    assert len(rows) == len(spec["variants"]) * len(spec.get("inputs") or {"default": {}})
    failed = {f"{r['variant']}/{r['input']}": r.get("error") for r in rows if r["status"] != "ok"}
    assert failed == {}
    assert all(isinstance(r.get("mpjpe_mm"), float) for r in rows)
    assert (tmp_path / "out" / "results.md").is_file() and (tmp_path / "out" / "results.png").is_file()


def test_study_set_reaches_every_run_and_errors_are_whole(tmp_path):
    rows = run_study(ROOT / "studies" / "calibrators.yaml", tmp_path / "o", cache=Cache(tmp_path / "c"), sets={"decoed.stop": 60})
    assert {r["status"] for r in rows} == {"failed"}
    assert "unknown node 'decoed' (did you mean 'decode'?)" in rows[0]["error"]
