"""A ground truth applies only to the video it belongs to (issue 14, item 3)."""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.io.ground_truth import ground_truth

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "data" / "sample"


def test_bundled_truth_records_the_bundled_video():
    gt = np.load(SAMPLE / "ground_truth.npz")
    video = (SAMPLE / "sample.mp4").read_bytes()
    assert str(gt["video_sha256"]) == hashlib.sha256(video).hexdigest()
    assert int(gt["video_bytes"]) == len(video)
    assert int(gt["video_frames"]) == gt["joints3d_world"].shape[0] == 210


def test_truth_with_its_own_video_is_read():
    out = run_node(ground_truth, params={"path": str(SAMPLE / "ground_truth.npz"), "video": str(SAMPLE / "sample.mp4"),
                                         "start": 5, "stop": 50})["truth"]
    assert out["joints3d_world"].shape == (45, 16, 3)


def test_truth_of_another_video_is_an_error_with_the_way_out(tmp_path):
    own = tmp_path / "take1.mp4"
    data = bytearray((SAMPLE / "sample.mp4").read_bytes())
    data[-100] ^= 0xFF  # same size, one byte different
    own.write_bytes(bytes(data))
    with pytest.raises(NodeError, match="belongs to another video") as e:
        run_node(ground_truth, params={"path": str(SAMPLE / "ground_truth.npz"), "video": str(own)})
    assert "ground_truth=null" in e.value.hint
    short = tmp_path / "short.mp4"
    short.write_bytes(bytes(data[:1000]))
    with pytest.raises(NodeError, match="1,000 bytes"):
        run_node(ground_truth, params={"path": str(SAMPLE / "ground_truth.npz"), "video": str(short)})


def test_truth_that_records_no_video_is_refused_when_a_video_is_given(tmp_path):
    d = dict(np.load(SAMPLE / "ground_truth.npz"))
    for k in ("video_sha256", "video_bytes", "video_frames"):
        d.pop(k)
    old = tmp_path / "old.npz"
    np.savez(old, **d)
    with pytest.raises(NodeError, match="does not record which video"):
        run_node(ground_truth, params={"path": str(old), "video": str(SAMPLE / "sample.mp4")})


def test_default_pipeline_with_an_own_video_and_the_default_truth_fails_clearly(tmp_path):
    """`--var video=own.mp4` without `--var ground_truth=null` must not score the take against the sample."""
    from tbha_graph.core.errors import NodeFailed
    from tbha_graph.core.runner import load_graph, run_graph

    own = tmp_path / "own.mp4"
    shutil.copy(SAMPLE / "sample.mp4", own)
    with open(own, "ab") as f:
        f.write(b"\0")
    g = load_graph(ROOT / "pipelines" / "default.yaml", vars={"video": str(own)})
    with pytest.raises(NodeFailed, match="belongs to another video"):
        run_graph(g, outputs=["truth"], cache=False)


def test_the_renderer_records_its_video(tmp_path):
    from test_render import CLEAN, front_camera, render, standing_tpose

    motion = np.repeat(standing_tpose()[None], 3, axis=0)
    video, gt = render(tmp_path, motion, front_camera(160, 120, 180.0), **CLEAN)
    assert str(gt["video_sha256"]) == hashlib.sha256(Path(video).read_bytes()).hexdigest()
    assert int(gt["video_bytes"]) == Path(video).stat().st_size and int(gt["video_frames"]) == 3
    np.savez(tmp_path / "gt.npz", **gt)
    assert run_node(ground_truth, params={"path": str(tmp_path / "gt.npz"), "video": str(video)})["truth"]["joints3d_world"].shape[0] == 3
