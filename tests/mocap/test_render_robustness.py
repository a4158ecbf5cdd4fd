"""Failures found by ``bench/render_robustness.py`` on renders unlike ours, kept fixed.

Each test renders a few frames of the opening T-pose with the project's renderer, changes the one thing
that broke the capture, and checks the stage that broke. Small renders: the file runs in a few seconds.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.segment.balance import choose_balance
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity
from tbha_graph.mocap.io.video import video
from tbha_graph.mocap.segment.hierarchical import HierarchicalParams, segment_clip
from tbha_graph.mocap.skeleton import JOINT_INDEX, PATCHED_JOINTS
from tbha_graph.mocap.suit import load_suit
from tbha_graph.mocap.synth.render import RenderParams, render_video
from tbha_graph.mocap.synth.tpose_lead_in import LeadInParams, lead_in_motion

ROOT = Path(__file__).resolve().parents[2]
BVH = ROOT / "data" / "mocap" / "cmu" / "131_02.bvh"
N_FRAMES = 8


@pytest.fixture(scope="module")
def tpose_render(tmp_path_factory):
    """(frames, truth): the sample's camera and settings, the first N_FRAMES frames of the opening T-pose."""
    folder = tmp_path_factory.mktemp("tpose")
    joints, fps = lead_in_motion(LeadInParams(path=BVH, hold_seconds=1.0, blend_seconds=0.5, duration=0.2))
    cam = Camera.look_at((0.8, 1.45, 4.6), (0.0, 0.95, 0.0), focal_px=700.0, width=640, height=480)
    path = folder / "tpose.mp4"
    truth = render_video(joints[: int(N_FRAMES * fps / 30.0) + 1], fps, cam, load_suit(), RenderParams(), path)
    cap = cv2.VideoCapture(str(path))
    frames = []
    while len(frames) < N_FRAMES:
        ok, f = cap.read()
        assert ok
        frames.append(f)
    cap.release()
    return frames, truth


def _clip(tmp_path: Path, frames: list[np.ndarray], gains_rgb=None):
    """A lossless clip of ``frames``, each channel multiplied by ``gains_rgb`` (a coloured light)."""
    g = np.ones(3, np.float32) if gains_rgb is None else np.asarray(gains_rgb, np.float32)[::-1]
    path = tmp_path / "clip.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 30.0, (frames[0].shape[1], frames[0].shape[0]))
    for f in frames:
        w.write(np.clip(f * g + 0.5, 0, 255).astype(np.uint8))
    w.release()
    return run_node(video, {"path": str(path)})["video"]


def _patch_errors(model, det, truth) -> np.ndarray:
    """(n, 15) px: each visible patch's true centre to the nearest candidate of its colour (inf: none)."""
    centres = det["centres"]
    err = np.full((len(centres), len(PATCHED_JOINTS)), np.inf)
    for c, cls in enumerate(model.classes):
        for name in cls.joints:
            if name not in PATCHED_JOINTS:
                continue
            p = PATCHED_JOINTS.index(name)
            d = np.linalg.norm(centres[:, c] - truth["patch2d"][: len(centres), None, p], axis=-1)
            err[:, p] = np.nanmin(np.where(np.isnan(d), np.inf, d), axis=1)
    return np.where(truth["patch_visible"][: len(centres)], err, 0.0)


#: a tungsten-like light (or a camera balanced for daylight under it): the render that failed at its T-pose
WARM = (1.0, 0.82, 0.6)
COOL = (0.75, 0.9, 1.0)


@pytest.mark.parametrize("gains", [WARM, COOL], ids=["warm", "cool"])
def test_coloured_light_patches_found(tmp_path, tpose_render, gains):
    """Under a coloured light every patch is found where it is (the suit's white is balanced back); without the
    correction the same frames lose or mislabel patches (the failure this guards against)."""
    frames, truth = tpose_render
    model = run_node(rg_chromaticity)["model"]
    clip = _clip(tmp_path, frames, gains)
    err = _patch_errors(model, segment_clip(clip, model, HierarchicalParams()), truth)
    # measured: worst 2.0 px (warm and cool; 2.0 px on the untinted frames too), median 0.4 px
    assert err.max() < 3.0, f"worst patch {err.max():.1f} px from the truth"
    off = _patch_errors(model, segment_clip(clip, model, HierarchicalParams(white_balance="off")), truth)
    assert off.max() > 5.0


def test_white_balance_leaves_our_renders_alone(tmp_path, tpose_render):
    """On a render with a white light no correction is applied (the segmenter reads exactly the video)."""
    frames, _ = tpose_render
    model = run_node(rg_chromaticity)["model"]
    b = choose_balance(frames[:4], model)
    assert b.gains is None, b.describe()
    warm = [np.clip(f * np.float32(WARM[::-1]) + 0.5, 0, 255).astype(np.uint8) for f in frames[:4]]
    b = choose_balance(warm, model)
    assert b.gains is not None
    assert np.allclose(b.gains[::-1] * WARM, (b.gains[::-1] * WARM).mean(), rtol=0.06), b.describe()  # undoes the tint


def _wash_out(frames, truth, joint: str, radius_px: float = 9.0):
    """The frames with ``joint``'s patch painted over by the suit around it (a patch washed out to white by a
    strong light, as the neck patch facing the key light was in the harsh-light render)."""
    p = PATCHED_JOINTS.index(joint)
    out = []
    for t, f in enumerate(frames):
        f = f.copy()
        x, y = truth["patch2d"][t, p]
        yy, xx = np.mgrid[: f.shape[0], : f.shape[1]]
        d = np.hypot(xx - x, yy - y)
        ring = (d > radius_px + 2) & (d < radius_px + 5)
        f[d <= radius_px] = np.median(f[ring], axis=0).astype(np.uint8)
        out.append(f)
    return out


def test_start_with_a_washed_out_patch(tmp_path, tpose_render):
    """A patch never seen in the opening (washed out) no longer stops the take: the T-pose is found with that joint
    placed by the T-pose template (not tracked), its same-coloured partner keeps its own blob, the rest are tracked."""
    from tbha_graph.mocap.track.posture_kalman import posture_kalman

    frames, truth = tpose_render
    model = run_node(rg_chromaticity)["model"]
    clip = _clip(tmp_path, _wash_out(frames, truth, "neck"))
    det = segment_clip(clip, model, HierarchicalParams())
    tracks = run_node(posture_kalman, {"require_tpose": True}, detections=det, colors=model)["tracks"]
    neck = JOINT_INDEX["neck"]
    assert not tracks["tracked"][:, neck].any()
    others = [JOINT_INDEX[j] for j in PATCHED_JOINTS if j != "neck"]
    assert tracks["tracked"][:, others].all()
    err = np.linalg.norm(tracks["points"][:, others] - truth["patch2d"][:N_FRAMES, [PATCHED_JOINTS.index(j) for j in PATCHED_JOINTS if j != "neck"]], axis=-1)
    assert err.max() < 3.0  # measured 2.0 px: the hips patch (orange, like the neck) kept its identity
    # the template puts the neck near its patch (the template's proportions are the default body's)
    assert np.linalg.norm(tracks["points"][0, neck] - truth["patch2d"][0, PATCHED_JOINTS.index("neck")]) < 15.0
    # without the fallback the take stops at its T-pose, naming the patch
    with pytest.raises(Exception, match="hips / neck"):
        run_node(posture_kalman, {"require_tpose": True, "max_missing": 0}, detections=det, colors=model)
