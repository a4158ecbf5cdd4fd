"""Patch segmenters on synthetic tight-suit frames: discs with highlights, blur and noise."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.color.hsv import hsv
from tbha_graph.mocap.color.lab import lab
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity
from tbha_graph.mocap.io.video import video
from tbha_graph.mocap.segment.chroma_threshold import ChromaThresholdParams, chroma_threshold, threshold_frame
from tbha_graph.mocap.segment.hierarchical import HierarchicalParams, HierarchicalSegmenter, hierarchical
from tbha_graph.mocap.segment.labels import PixelClassifier
from tbha_graph.mocap.segment.refine import farthest_peaks
from tbha_graph.mocap.segment.testframes import draw_frame, tpose_points, write_video
from tbha_graph.mocap.skeleton import JOINT_INDEX, N_JOINTS
from tbha_graph.mocap.suit import load_suit

SEGMENTERS = {"hierarchical": hierarchical, "chroma_threshold": chroma_threshold}


@pytest.fixture(scope="module")
def model():
    return run_node(rg_chromaticity)["model"]


def _errors(model, centres: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per joint, distance (px) from the true centre to the nearest candidate of its colour: (n, 16)."""
    n = len(truth)
    err = np.full((n, N_JOINTS), np.inf)
    for c, cls in enumerate(model.classes):
        for name in cls.joints:
            j = JOINT_INDEX[name]
            d = np.linalg.norm(centres[:, c] - truth[:, None, j], axis=-1)  # (n, K), NaN in empty slots
            err[:, j] = np.nanmin(np.where(np.isnan(d), np.inf, d), axis=1)
    return err


def _moving_clip(tmp_path, n=8, step=(3.0, 1.5), hidden=None):
    """A lossless (FFV1) clip of the T-pose drifting by ``step`` px per frame; ``hidden`` maps
    frame -> joint names whose patch is not drawn."""
    p0 = tpose_points()
    truth = np.array([p0 + np.asarray(step) * t for t in range(n)])
    frames = []
    for t in range(n):
        vis = np.ones(N_JOINTS, bool)
        for name in (hidden or {}).get(t, ()):
            vis[JOINT_INDEX[name]] = False
        frames.append(draw_frame(truth[t], visible=vis, rng=np.random.default_rng(t)))
    path = tmp_path / "clip.avi"
    write_video(path, frames, fourcc="FFV1")
    return run_node(video, {"path": str(path)})["video"], truth


@pytest.mark.parametrize("kind", sorted(SEGMENTERS))
def test_finds_every_disc_within_1px(tmp_path, model, kind):
    clip, truth = _moving_clip(tmp_path)
    det = run_node(SEGMENTERS[kind], video=clip, colors=model)["detections"]
    n_cls = len(model.classes)
    assert det["centres"].shape[:2] == (len(truth), n_cls) and det["centres"].shape[-1] == 2
    assert det["areas"].shape == det["centres"].shape[:3] and det["boxes"].shape[-1] == 4
    assert list(det["colour_names"]) == model.names
    assert list(det["frame_index"]) == list(range(len(truth)))
    assert (int(det["width"]), int(det["height"]), float(det["fps"])) == (640, 480, 30.0)
    err = _errors(model, det["centres"], truth)
    patches = [JOINT_INDEX[n] for n in JOINT_INDEX if n != "head"]
    assert err[:, patches].max() < 1.0, err.max(axis=0)
    assert err[:, JOINT_INDEX["head"]].max() < 1.0  # the dark head disc
    # every class holds exactly as many candidates as joints wear it (no spurious regions)
    counts = np.isfinite(det["centres"][..., 0]).sum(axis=2)
    assert (counts == [len(c.joints) for c in model.classes]).all()


def _disc_with_highlight(colour: str, centre, radius=9.0, offset=0.6, hl_radius=0.4, seed=0):
    """A patch on the white suit whose highlight cuts into its rim (the case clustering alone gets wrong)."""
    img = np.full((120, 160, 3), 236, np.uint8)
    s = 16
    bgr = tuple(float(v) for v in (load_suit().rgb(colour) * 255 * 0.85)[::-1])
    c = np.asarray(centre, dtype=np.float64)
    cv2.circle(img, (int(c[0] * s), int(c[1] * s)), int(radius * s), bgr, -1, cv2.LINE_AA, 4)
    hp = c - offset * radius
    cv2.circle(img, (int(hp[0] * s), int(hp[1] * s)), int(hl_radius * radius * s), (250, 250, 250), -1, cv2.LINE_AA, 4)
    img = cv2.GaussianBlur(img, (3, 3), 0.7)
    rng = np.random.default_rng(seed)
    return np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("colour", ["red", "yellow", "blue", "purple", "cyan"])
def test_highlight_on_the_rim(model, colour):
    centre = (80.3, 60.6)
    img = _disc_with_highlight(colour, centre)
    k = model.names.index(colour)
    seg = HierarchicalSegmenter(model, HierarchicalParams(), 160, 120)
    found = [pos for c, pos, _, _ in seg.process(img) if c == k]
    assert len(found) == 1 and np.linalg.norm(found[0] - centre) < 1.0
    regions = threshold_frame(img, PixelClassifier(model), ChromaThresholdParams())[k]
    assert len(regions.areas) == 1 and np.linalg.norm(regions.centres[0] - centre) < 1.0
    # plain thresholding without the convex hull is pulled away from the highlight
    raw = threshold_frame(img, PixelClassifier(model), ChromaThresholdParams(convex_hull=False, close_px=0))[k]
    assert np.linalg.norm(raw.centres[0] - centre) > np.linalg.norm(regions.centres[0] - centre)


@pytest.mark.parametrize("node", [hsv, lab], ids=["hsv", "lab"])
def test_other_colour_spaces(tmp_path, node):
    model = run_node(node)["model"]
    clip, truth = _moving_clip(tmp_path, n=4)
    det = run_node(hierarchical, video=clip, colors=model)["detections"]
    assert _errors(model, det["centres"], truth).max() < 1.0


def test_lost_patch_is_found_again(tmp_path, model):
    hidden = {t: ("left_wrist",) for t in (3, 4, 5)}
    clip, truth = _moving_clip(tmp_path, n=10, step=(4.0, 0.0), hidden=hidden)
    det = run_node(hierarchical, video=clip, colors=model, params={"lost_search_every": 1, "full_search_every": 0})["detections"]
    err = _errors(model, det["centres"], truth)
    j = JOINT_INDEX["left_wrist"]
    magenta = model.names.index("magenta")
    counts = np.isfinite(det["centres"][:, magenta, :, 0]).sum(axis=1)
    assert list(counts[3:6]) == [1, 1, 1]  # only the ankle while the wrist is hidden
    assert np.all(err[:3, j] < 1.0) and np.all(err[6:, j] < 1.0)  # back as soon as it reappears
    others = [i for i in range(N_JOINTS) if i != j]
    assert err[:, others].max() < 1.0


def test_fast_motion_is_followed(tmp_path, model):
    # 12 px per frame: far beyond a patch's radius, within the constant-velocity prediction
    clip, truth = _moving_clip(tmp_path, n=8, step=(12.0, -3.0))
    det = run_node(hierarchical, video=clip, colors=model, params={"full_search_every": 0})["detections"]
    assert _errors(model, det["centres"], truth).max() < 1.0


def test_farthest_peaks():
    h = np.array([[0, 5, 2, 2, 1, 2, 7, 0], [0, 0, 0, 0, 0, 0, 0, 0], [0, 1, 6, 2, 2, 2, 6, 1]], float)
    lo, hi = farthest_peaks(h, 0.5)
    assert lo[0] == pytest.approx(1 + (2 - 0) / 7) and hi[0] == pytest.approx(6 + (0 - 2) / 9)
    assert np.isnan(lo[1]) and np.isnan(hi[1])
    assert lo[2] == pytest.approx(2 + (2 - 1) / 9) and hi[2] == pytest.approx(6 + (1 - 2) / 9)
    # a spur below the fraction is not a peak
    lo, hi = farthest_peaks(np.array([[1, 0, 6, 2, 2, 6, 0, 1]], float), 0.3)
    assert lo[0] == pytest.approx(2 + 2 / 8) and hi[0] == pytest.approx(5 - 2 / 8)


def test_bad_colour_model_input(tmp_path):
    from tbha_graph.core.errors import NodeError

    clip, _ = _moving_clip(tmp_path, n=1)
    with pytest.raises(NodeError, match="colour model"):
        run_node(hierarchical, video=clip, colors={"space": "xyz"})
    with pytest.raises(ValidationError, match=r"search_scale\n  Input should be greater than 0"):
        run_node(hierarchical, video=clip, colors={}, params={"search_scale": 0})


def test_threshold_at_half_resolution(tmp_path, model):
    clip, truth = _moving_clip(tmp_path, n=3)
    det = run_node(chroma_threshold, video=clip, colors=model, params={"scale": 0.5})["detections"]
    assert _errors(model, det["centres"], truth).max() < 1.5


def test_window_params_checked():
    with pytest.raises(ValidationError, match="min_window"):
        HierarchicalParams(min_window=200, max_window=100)
