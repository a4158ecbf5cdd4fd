"""Every bundled pipeline runs end to end on a fresh checkout (the ones not already run by other tests)."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tbha_graph.core.cache import Cache
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.mocap.io.bvh import read_bvh

PIPELINES = Path(__file__).resolve().parents[2] / "pipelines"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return Cache(tmp_path_factory.mktemp("cache"))


def test_synthetic_renders_video_and_ground_truth(tmp_path, cache):
    g = load_graph(PIPELINES / "synthetic.yaml", sets={"motion.duration": 1.0})
    run_graph(g, out_dir=tmp_path / "run", cache=cache)
    cap = cv2.VideoCapture(str(tmp_path / "run" / "sample.mp4"))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    with np.load(tmp_path / "run" / "ground_truth.npz", allow_pickle=False) as z:
        assert z["joints2d"].shape == (n, 16, 2) and z["joints3d_world"].shape == (n, 16, 3)
    assert (cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (640, 480)


def test_retarget_writes_the_character_and_foot_figures(tmp_path, cache):
    g = load_graph(PIPELINES / "retarget.yaml")
    run_graph(g, out_dir=tmp_path / "run", outputs=["character.bvh", "metrics.json"], cache=cache)
    bvh = read_bvh(tmp_path / "run" / "character.bvh")
    assert any(name.startswith("mixamorig:") for name in bvh.names) and bvh.n_frames == 210
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["foot_sliding_after_mm"] <= m["foot_sliding_before_mm"]


def test_evaluate_render_scores_a_fresh_render(tmp_path, cache):
    g = load_graph(PIPELINES / "evaluate_render.yaml", sets={"lead_in.duration": 2.0})
    run = run_graph(g, out_dir=tmp_path / "run", outputs=["metrics.json"], cache=cache)
    m = run.output("metrics.json")
    assert m["frames"] == 90  # 1 s held T-pose + 2 s of clip (the blend overlaps the clip), 30 fps
    assert np.isfinite(m["pa_mpjpe_mm"]) and m["tracking_2d_px_median"] < 2.0
