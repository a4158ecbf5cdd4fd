"""calibrate.camera_motion: a camera that moved (hand-held, bumped, panned) is measured and named; a still one is not."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tbha_graph.core.node import Context
from tbha_graph.core.runner import load_graph
from tbha_graph.core.scheduler import targets_of
from tbha_graph.mocap.calibrate.camera_motion import camera_motion, corner_shift
from tbha_graph.mocap.io.video import iter_frames, probe_video
from tbha_graph.mocap.segment.testframes import write_video

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "data" / "sample" / "sample.mp4"
TRUTH = ROOT / "data" / "sample" / "ground_truth.npz"
N = 90  # frames of the sample used


def _run(path, tracks=None, **params):
    ctx = Context("still", camera_motion.params.model_validate(params))
    report = camera_motion.fn(ctx, probe_video(path, stop=N), tracks)["report"]
    return report, ctx


def _moved_copy(path: Path, motions: np.ndarray) -> Path:
    """The sample's first N frames, frame i moved by the 2x3 similarity ``motions[i]`` (a camera's motion)."""
    frames = [cv2.warpAffine(f, motions[i], (f.shape[1], f.shape[0]), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
              for i, f in iter_frames(probe_video(SAMPLE, stop=N))]
    write_video(path, frames, fps=30.0)
    return path


def _similarity(angle_deg: float, dx: float, dy: float) -> np.ndarray:
    m = cv2.getRotationMatrix2D((320.0, 240.0), angle_deg, 1.0)
    m[:, 2] += (dx, dy)
    return m


def _truth_tracks():
    with np.load(TRUTH, allow_pickle=False) as z:
        points = z["joints2d"][:N]
    return {"points": points, "tracked": np.ones(points.shape[:2], bool), "fps": np.array(30.0),
            "width": np.array(640), "height": np.array(480)}


def test_the_bundled_samples_still_camera_is_still():
    report, ctx = _run(SAMPLE)
    assert not report["camera_moved"] and ctx.warnings == []
    assert report["camera_shift_px"] < 0.28  # measured 0.19 (the codec's noise, and corners on the actor's edge)
    assert report["camera_motion_frames_judged"] == report["camera_motion_frames_sampled"] == 18
    masked, ctx = _run(SAMPLE, _truth_tracks())  # the actor's box left out
    assert not masked["camera_moved"] and masked["camera_shift_px"] < 0.22 and ctx.warnings == []  # measured 0.15


def test_a_hand_held_camera_is_measured_and_named(tmp_path):
    """A slow pan (0.1 px a frame) with a hand's tremor (1 px, 0.1 degree): the shift per sampled frame is the
    motion's own, and the warning says how far and where."""
    rng = np.random.default_rng(3)
    motions = np.array([_similarity(rng.normal(0, 0.1), 0.1 * i + rng.normal(0, 1.0), rng.normal(0, 1.0)) for i in range(N)])
    motions[0] = _similarity(0, 0, 0)
    path = _moved_copy(tmp_path / "hand_held.mp4", motions)
    report, ctx = _run(path, _truth_tracks())
    assert report["camera_moved"]
    frames = np.array(report["frames"])
    want = np.array([corner_shift(motions[f], 640, 480) for f in frames])
    got = np.array(report["shift_px"], float)
    assert np.abs(got - want).max() < 0.35  # measured 0.24 (max shift 9.31 px against 9.31)
    (warning,) = ctx.warnings
    assert f"up to {got.max():.1f} px from frame 0's" in warning and "tripod" in warning


def test_a_bump_halfway_names_the_frames_after_it(tmp_path):
    motions = np.array([_similarity(0, 0, 0) if i < 45 else _similarity(0.0, 4.0, -3.0) for i in range(N)])
    report, ctx = _run(_moved_copy(tmp_path / "bumped.mp4", motions))
    assert report["camera_moved"] and abs(report["camera_shift_px"] - 5.0) < 0.2  # measured 5.13
    assert "sampled frames 45-89" in ctx.warnings[0]
    assert all(s < 0.3 for f, s in zip(report["frames"], report["shift_px"]) if f < 45)  # measured 0.20


def test_a_plain_background_cannot_be_judged_and_says_so(tmp_path):
    frames = []
    for i in range(30):
        f = np.full((240, 320, 3), 128, np.uint8)
        cv2.circle(f, (60 + 5 * i, 120), 20, (0, 0, 255), -1)  # something moves, on nothing to follow
        frames.append(f)
    path = tmp_path / "plain.mp4"
    write_video(path, frames, fps=30.0)
    ctx = Context("still", camera_motion.params.model_validate({}))
    report = camera_motion.fn(ctx, probe_video(path), None)["report"]
    assert report["camera_shift_px"] is None and not report["camera_moved"] and ctx.warnings == []


@pytest.mark.parametrize("pipeline", ["default.yaml", "mediapipe.yaml"])
def test_the_user_pipelines_measure_it_and_report_it_in_metrics(pipeline):
    graph = load_graph(ROOT / "pipelines" / pipeline)
    assert graph.nodes["still"].spec.type == "calibrate.camera_motion"
    assert graph.nodes["metrics"].inputs["camera_motion"] == ("still", "report")
    assert "still" in graph.needed_for(targets_of(graph, None))  # it runs whenever metrics.json is written
