"""The opening T-pose is found, and a take without one fails clearly (issue 14, item 4)."""
from __future__ import annotations

from pathlib import Path

import pytest

from tbha_graph.core.errors import NodeFailed
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.mocap.tpose import find_tpose, tpose_frames

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sample_tracks(tmp_path_factory):
    from tbha_graph.core.cache import Cache

    cache = Cache(tmp_path_factory.mktemp("cache"))
    g = load_graph(ROOT / "pipelines" / "default.yaml", sets={"decode.stop": 120})
    return run_graph(g, outputs=["track"], cache=cache).output("track.tracks"), cache


def test_the_samples_opening_tpose_is_found(sample_tracks):
    t, _ = sample_tracks
    first, last = find_tpose(t["points"], t["tracked"], float(t["fps"]))
    assert first == 0 and 25 <= last <= 45  # 1 s hold, then the blend into the walk (measured: 0-33)


def test_frames_after_the_tpose_are_not_one(sample_tracks):
    t, _ = sample_tracks
    assert not tpose_frames(t["points"][60:], t["tracked"][60:]).any()
    assert find_tpose(t["points"][60:], t["tracked"][60:], float(t["fps"])) is None


def test_a_back_view_or_lowered_arms_are_not_a_tpose(sample_tracks):
    t, _ = sample_tracks
    p = t["points"][:30].copy()
    mirrored = p.copy()
    mirrored[..., 0] = 640 - mirrored[..., 0]  # seen from behind: left shoulder on the image's left
    assert not tpose_frames(mirrored, t["tracked"][:30]).any()
    from tbha_graph.mocap.skeleton import JOINT_INDEX as J

    low = p.copy()
    for j in ("left_wrist", "right_wrist"):
        low[:, J[j], 1] += 80  # arms hanging down
    assert not tpose_frames(low, t["tracked"][:30]).any()


def test_default_pipeline_without_an_opening_tpose_fails_with_the_way_out(sample_tracks):
    _, cache = sample_tracks
    g = load_graph(ROOT / "pipelines" / "default.yaml", sets={"decode.start": 60, "decode.stop": 180})
    with pytest.raises(NodeFailed) as e:
        run_graph(g, outputs=["track"], cache=cache)
    assert "no T-pose facing the camera" in e.value.message and e.value.node == "track"
    assert "decode.start" in e.value.hint and "track.require_tpose=false" in e.value.hint
    g = load_graph(ROOT / "pipelines" / "default.yaml", sets={"decode.start": 60, "decode.stop": 180, "track.require_tpose": False})
    assert run_graph(g, outputs=["track"], cache=cache).output("track.tracks")["points"].shape == (120, 16, 2)
