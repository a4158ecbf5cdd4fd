"""Issue 13: suits whose patches share colours (both kinds), and what the suit file may declare."""
from __future__ import annotations

from pathlib import Path

import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.mocap.suit import DEFAULT_SUIT_PATH, SEED_SUIT_PATH, load_suit


def test_both_bundled_suit_kinds_load():
    assert load_suit(DEFAULT_SUIT_PATH).sharing_kind == "upper_lower"
    seed = load_suit(SEED_SUIT_PATH)
    assert seed.sharing == "left_right" and seed.sharing_kind == "left_right"
    assert seed.joints_by_colour()["red"] == ["left_shoulder", "right_shoulder"]


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = SEED_SUIT_PATH.read_text()
    assert old in text
    p = tmp_path / "suit.yaml"
    p.write_text(text.replace(old, new))
    return p


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_unresolvable_sharing_names_file_and_line(tmp_path):
    # left_elbow and right_wrist in one colour: neither a mirror pair nor an upper/lower pair
    p = _edited(tmp_path, "right_wrist: magenta", "right_wrist: blue")
    p.write_text(p.read_text().replace("right_elbow: blue", "right_elbow: magenta"))
    with pytest.raises(NodeError) as e:
        load_suit(p)
    assert str(p) in str(e.value) and "left_elbow and right_wrist" in str(e.value)
    assert e.value.location.line == _line_of(p, "right_wrist:")


def test_three_patches_in_one_colour_refused(tmp_path):
    p = _edited(tmp_path, "chest: purple", "chest: orange")
    with pytest.raises(NodeError, match="3 patches") as e:
        load_suit(p)
    assert e.value.location.line == _line_of(p, "chest:")


def test_declared_kind_must_match(tmp_path):
    p = _edited(tmp_path, "sharing: left_right", "sharing: upper_lower")
    with pytest.raises(NodeError, match="left_right pair but the suit declares 'sharing: upper_lower'") as e:
        load_suit(p)
    assert e.value.location.line == _line_of(p, "right_shoulder:")
    p.write_text(p.read_text().replace("sharing: upper_lower", "sharing: mixed"))
    assert load_suit(p).sharing_kind == "left_right"


# --------------------------------------------------------------------------------------------
# tracking with shared colours, losses and turns (track.posture_kalman on synthetic detections)
import numpy as np  # noqa: E402

from tbha_graph.core.testing import run_node  # noqa: E402
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity  # noqa: E402
from tbha_graph.mocap.segment.testframes import tpose_points  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, N_JOINTS, PARENTS  # noqa: E402
from tbha_graph.mocap.track.common import DOUBT  # noqa: E402
from tbha_graph.mocap.track.posture_kalman import posture_kalman  # noqa: E402

J = JOINT_INDEX


@pytest.fixture(scope="module")
def seed_model():
    return run_node(rg_chromaticity, {"suit": str(SEED_SUIT_PATH)})["model"]


@pytest.fixture(scope="module")
def default_model():
    return run_node(rg_chromaticity)["model"]


def _detections(model, truth, visible=None, seed=0):
    """One candidate per visible joint at its true pixel, slots shuffled."""
    n = len(truth)
    visible = np.ones((n, N_JOINTS), bool) if visible is None else visible
    rng = np.random.default_rng(seed)
    C, K = len(model.classes), 3
    centres = np.full((n, C, K, 2), np.nan, np.float32)
    areas = np.zeros((n, C, K), np.float32)
    for t in range(n):
        for c, cls in enumerate(model.classes):
            pts = [truth[t, J[j]] for j in cls.joints if visible[t, J[j]]]
            for k, i in enumerate(rng.permutation(len(pts))):
                centres[t, c, k] = pts[i]
                areas[t, c, k] = 100.0
    return {"centres": centres, "areas": areas, "boxes": np.full((n, C, K, 4), np.nan, np.float32),
            "colour_names": np.array(model.names), "frame_index": np.arange(n), "fps": np.asarray(30.0),
            "width": np.asarray(640), "height": np.asarray(480)}


def _rotated(points, deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    centre = np.array([320.0, 240.0])
    return (points - centre) @ np.array([[c, s], [-s, c]]) + centre


def test_seed_suit_start_tells_left_from_right_on_a_tilted_t_pose(seed_model):
    # the camera rolled 6 degrees: one shoulder's patch is higher in the image than the other's, which
    # must not make the posture rules take height order within a left/right pair
    truth = np.repeat(_rotated(tpose_points(), -6.0)[None], 4, axis=0)
    assert abs(truth[0, J["right_shoulder"], 1] - truth[0, J["left_shoulder"], 1]) > 5
    out = run_node(posture_kalman, detections=_detections(seed_model, truth), colors=seed_model)["tracks"]
    np.testing.assert_allclose(out["points"], truth, atol=1e-3)


def test_lost_joint_follows_the_body_never_off_it(default_model):
    # the actor moves sideways 3 px a frame; the left wrist is hidden from frame 10 to 49
    n = 60
    truth = tpose_points()[None] + np.arange(n)[:, None, None] * np.array([3.0, 0.0])
    visible = np.ones((n, N_JOINTS), bool)
    hidden = np.arange(10, 50)
    visible[hidden, J["left_wrist"]] = False
    out = run_node(posture_kalman, detections=_detections(default_model, truth, visible), colors=default_model)["tracks"]
    assert not out["tracked"][hidden, J["left_wrist"]].any()
    forearm = np.linalg.norm(truth[0, J["left_wrist"]] - truth[0, J["left_elbow"]])
    reach = np.linalg.norm(out["points"][:, J["left_wrist"]] - out["points"][:, J["left_elbow"]], axis=1)
    assert reach.max() < 1.2 * forearm + 1.0  # extrapolation alone leaves it ~100 px behind the elbow
    err = np.linalg.norm(out["points"][hidden, J["left_wrist"]] - truth[hidden, J["left_wrist"]], axis=1)
    assert err.max() < 8.0  # placed from the elbow by its last seen offset
    assert (out["doubtful"][hidden[6:]] & DOUBT["lost joints"]).all()
    assert out["tracked"][50:].all()


@pytest.mark.parametrize("facing", ["front", "back"])
def test_left_right_suit_reacquired_after_a_turn(seed_model, facing):
    """Seed suit: every patch vanishes for 12 frames (the actor turning), then the body is seen again
    40 px further right, facing the camera again, or with the back to it (left on the image's left, the
    chest patch hidden): every identity is right within 5 frames of the patches' return."""
    p0 = tpose_points()
    n0, gap, n1 = 10, 12, 15
    back = p0.copy()
    back[:, 0] = 2 * p0[J["chest"], 0] - p0[:, 0]  # mirrored about the body's middle
    after = (p0 if facing == "front" else back) + np.array([40.0, 0.0])
    truth = np.concatenate([np.repeat(p0[None], n0 + gap, 0), np.repeat(after[None], n1, 0)])
    visible = np.ones((len(truth), N_JOINTS), bool)
    visible[n0 : n0 + gap] = False
    if facing == "back":
        visible[n0 + gap :, J["chest"]] = False
    out = run_node(posture_kalman, detections=_detections(seed_model, truth, visible), colors=seed_model)["tracks"]
    back_at = n0 + gap
    ok = out["tracked"] & (np.linalg.norm(out["points"] - truth, axis=2) < 1.0)
    settled = back_at + 5
    want = visible[settled:]
    assert (ok[settled:] == want).all(), np.argwhere(ok[settled:] != want)
    # and no joint was ever given another one's patch
    wrong = out["tracked"] & ~ok
    assert not wrong.any(), np.argwhere(wrong)
    # while lost, every point stays within reach of its parent
    for j in range(1, N_JOINTS):
        d = np.linalg.norm(out["points"][:, j] - out["points"][:, PARENTS[j]], axis=1)
        assert d.max() < 1.3 * np.linalg.norm(p0[j] - p0[PARENTS[j]]) + 25.0, j
