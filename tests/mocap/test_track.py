"""2D trackers: posture rules on the start frame, identities through crossings and occlusions."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity
from tbha_graph.mocap.io.video import video
from tbha_graph.mocap.segment.chroma_threshold import chroma_threshold
from tbha_graph.mocap.segment.hierarchical import hierarchical
from tbha_graph.mocap.segment.testframes import draw_frame, tpose_points, write_video
from tbha_graph.mocap.skeleton import JOINT_INDEX, N_JOINTS
from tbha_graph.mocap.track.nearest import nearest
from tbha_graph.mocap.track.posture_kalman import posture_kalman

TRACKERS = {"posture_kalman": posture_kalman, "nearest": nearest}
WRIST, ANKLE = JOINT_INDEX["left_wrist"], JOINT_INDEX["left_ankle"]  # both magenta on the default suit


@pytest.fixture(scope="module")
def model():
    return run_node(rg_chromaticity)["model"]


def detections_from(model, truth, visible=None, merge_px=0.0, seed=0):
    """A detections bundle made from true joint pixels (n, 16, 2): one candidate per visible joint,
    slots shuffled; same-coloured patches closer than ``merge_px`` become one candidate at their midpoint."""
    n = len(truth)
    visible = np.ones((n, N_JOINTS), bool) if visible is None else visible
    rng = np.random.default_rng(seed)
    C, K = len(model.classes), 3
    centres = np.full((n, C, K, 2), np.nan, np.float32)
    areas = np.zeros((n, C, K), np.float32)
    for t in range(n):
        for c, cls in enumerate(model.classes):
            pts = [truth[t, JOINT_INDEX[j]] for j in cls.joints if visible[t, JOINT_INDEX[j]]]
            if len(pts) == 2 and np.linalg.norm(pts[0] - pts[1]) < merge_px:
                pts = [(pts[0] + pts[1]) / 2]
            for k, i in enumerate(rng.permutation(len(pts))):
                centres[t, c, k] = pts[i]
                areas[t, c, k] = 100.0
    return {
        "centres": centres, "areas": areas, "boxes": np.full((n, C, K, 4), np.nan, np.float32),
        "colour_names": np.array(model.names), "frame_index": np.arange(n), "fps": np.asarray(30.0),
        "width": np.asarray(640), "height": np.asarray(480),
    }


def _still(n):
    return np.repeat(tpose_points()[None], n, axis=0)


def test_crossing_same_coloured_patches_keep_identities(model):
    # the left wrist swings down and the left ankle up: they cross at frame 15 (merged for 3 frames)
    n = 30
    truth = _still(n)
    meet = np.array([380.0, 280.0])
    t = np.arange(n)[:, None] - 15
    truth[:, WRIST] = meet + t * np.array([2.0, 7.0])
    truth[:, ANKLE] = meet + t * np.array([-1.5, -6.0])
    det = detections_from(model, truth, merge_px=14.0)
    out = run_node(posture_kalman, detections=det, colors=model)["tracks"]
    err = np.linalg.norm(out["points"] - truth, axis=2)
    merged = np.flatnonzero(np.linalg.norm(truth[:, WRIST] - truth[:, ANKLE], axis=1) < 14.0)
    assert len(merged) >= 1
    after = np.arange(merged.max() + 1, n)
    assert err[after][:, [WRIST, ANKLE]].max() < 1e-3  # each joint kept its own patch after the crossing
    assert out["tracked"][after].all()
    # while merged, one of them has the merged blob and the other is marked missing, never both tracked
    assert not (out["tracked"][merged][:, [WRIST, ANKLE]].all(axis=1)).any()


@pytest.mark.parametrize("kind", sorted(TRACKERS))
def test_occluded_patch_marked_missing_then_recovered(model, kind):
    n = 30
    truth = _still(n) + np.arange(n)[:, None, None] * np.array([2.0, 0.0])
    visible = np.ones((n, N_JOINTS), bool)
    hidden = np.arange(10, 16)
    visible[hidden, WRIST] = False  # its same-coloured partner (the ankle) stays visible
    det = detections_from(model, truth, visible)
    out = run_node(TRACKERS[kind], detections=det, colors=model)["tracks"]
    assert not out["tracked"][hidden, WRIST].any()
    assert out["tracked"][:, [i for i in range(N_JOINTS) if i != WRIST]].all()
    # never given the ankle's detection while hidden
    assert np.linalg.norm(out["points"][hidden, WRIST] - truth[hidden, ANKLE], axis=1).min() > 50
    back = np.arange(16, n)
    assert out["tracked"][back, WRIST].all()
    np.testing.assert_allclose(out["points"][back], truth[back], atol=1e-3)
    if kind == "posture_kalman":  # the prediction carries on while hidden (velocity fading)
        assert np.linalg.norm(out["points"][hidden[0], WRIST] - truth[hidden[0], WRIST]) < 1.0


def test_bundle_format(model):
    det = detections_from(model, _still(5))
    out = run_node(posture_kalman, detections=det, colors=model)["tracks"]
    assert out["points"].shape == (5, N_JOINTS, 2) and out["tracked"].shape == (5, N_JOINTS)
    assert out["tracked"].dtype == bool and float(out["fps"]) == 30.0
    assert (int(out["width"]), int(out["height"])) == (640, 480)
    np.testing.assert_allclose(out["points"], _still(5), atol=1e-4)


def _arms_down(p):
    """The T-pose with the arms hanging down beside the body (no T-pose)."""
    q = p.copy()
    for side in ("left", "right"):
        sh = p[JOINT_INDEX[f"{side}_shoulder"]]
        for k, j in enumerate(("elbow", "wrist")):
            q[JOINT_INDEX[f"{side}_{j}"]] = sh + np.array([0.0, 50.0 * (k + 1)])
    return q


@pytest.mark.parametrize("kind", sorted(TRACKERS))
def test_starts_at_the_t_pose_and_tracks_backwards(model, kind):
    n = 16
    p0 = tpose_points()
    down = _arms_down(p0)
    # frames 0..7: arms go from hanging down to the T-pose; frames 8..: T-pose
    w = np.clip(np.arange(n) / 8.0, 0, 1)[:, None, None]
    truth = down[None] * (1 - w) + p0[None] * w
    det = detections_from(model, truth)
    out = run_node(TRACKERS[kind], detections=det, colors=model)["tracks"]
    np.testing.assert_allclose(out["points"], truth, atol=1e-3)
    assert out["tracked"].all()


def test_no_t_pose_is_an_error(model):
    det = detections_from(model, np.repeat(_arms_down(tpose_points())[None], 6, axis=0))
    with pytest.raises(NodeError, match="no start T-pose.*not above the hips"):
        run_node(posture_kalman, detections=det, colors=model)


@pytest.mark.parametrize("shown, points_to_mediapipe", [(0, True), (4, True), (5, False)])
def test_a_video_without_the_suits_colours_points_to_the_mediapipe_pipeline(model, shown, points_to_mediapipe):
    # arms down (no T-pose) and only the first `shown` colour classes ever seen: with half of the colours or fewer
    # (a video of someone in ordinary clothes), the error says how many appear and names pipelines/mediapipe.yaml
    det = detections_from(model, np.repeat(_arms_down(tpose_points())[None], 6, axis=0))
    det["centres"][:, shown:] = np.nan
    with pytest.raises(NodeError) as err:
        run_node(posture_kalman, detections=det, colors=model)
    hint = err.value.hint or ""
    assert ("pipelines/mediapipe.yaml" in hint) is points_to_mediapipe
    if points_to_mediapipe:
        assert f"Only {shown} of the suit's {len(model.classes)} colours" in hint


def test_missing_patch_is_named(model):
    truth = _still(6)
    visible = np.ones((6, N_JOINTS), bool)
    visible[:, JOINT_INDEX["chest"]] = False
    visible[:, JOINT_INDEX["right_knee"]] = False
    with pytest.raises(NodeError, match=r"patches not found: .*chest") as e:
        run_node(nearest, detections=detections_from(model, truth, visible), colors=model)
    assert "right_knee" in str(e.value) and "init_frames" in str(e.value)


def test_detections_from_another_colour_model(model):
    det = detections_from(model, _still(3))
    det["colour_names"] = np.array(["a"] * len(model.names))
    with pytest.raises(NodeError, match="colour model"):
        run_node(posture_kalman, detections=det, colors=model)


def test_video_to_tracks(tmp_path, model):
    """The chain io.video -> color -> segment.hierarchical -> track.posture_kalman on a lossless clip."""
    n = 8
    p0 = tpose_points()
    truth = np.array([p0 + np.array([2.5, -1.0]) * t for t in range(n)])
    path = tmp_path / "clip.avi"
    write_video(path, [draw_frame(truth[t], rng=np.random.default_rng(t)) for t in range(n)], fourcc="FFV1")
    clip = run_node(video, {"path": str(path)})["video"]
    det = run_node(hierarchical, video=clip, colors=model)["detections"]
    out = run_node(posture_kalman, detections=det, colors=model)["tracks"]
    assert out["tracked"].all()
    assert np.linalg.norm(out["points"] - truth, axis=2).max() < 1.0


SAMPLE = Path(__file__).resolve().parents[2] / "data" / "sample"


@pytest.mark.skipif(not (SAMPLE / "sample.mp4").is_file() or not (SAMPLE / "ground_truth.npz").is_file(),
                    reason="data/sample/sample.mp4 + ground_truth.npz (rendered by synth.render_suit_video) not present")
@pytest.mark.parametrize("segmenter", [hierarchical, chroma_threshold], ids=["hierarchical", "chroma_threshold"])
def test_sample_video_accuracy(model, segmenter):
    """The whole 2D chain on the rendered sample, against its ground truth (visible patches only)."""
    from tbha_graph.mocap.skeleton import PATCHED_JOINTS

    with np.load(SAMPLE / "ground_truth.npz", allow_pickle=False) as z:
        gt = {k: z[k] for k in ("joints2d", "patch2d", "patch_visible")}
    clip = run_node(video, {"path": str(SAMPLE / "sample.mp4")})["video"]
    det = run_node(segmenter, video=clip, colors=model)["detections"]
    out = run_node(posture_kalman, detections=det, colors=model)["tracks"]
    patched = [JOINT_INDEX[j] for j in PATCHED_JOINTS]
    vis = gt["patch_visible"]
    pts = out["points"][:, patched]
    to_patch = np.linalg.norm(pts - gt["patch2d"], axis=2)[vis]
    to_joint = np.linalg.norm(pts - gt["joints2d"][:, patched], axis=2)[vis]
    assert np.median(to_patch) < 1.0 and np.percentile(to_patch, 95) < 3.0  # where the patches are
    assert out["tracked"][:, patched][vis].mean() > 0.98
    # the joints lie inside the body, a few px from the patch centres on its surface (the renderer
    # places each patch in front of its joint): a 2D tracker of patches cannot remove that offset
    assert np.median(to_joint) < 4.0
