"""The parts of detect.mediapipe_pose that need no MediaPipe: consistent left/right labels, the landmark
offsets fit and table, the reader thread, the solver's point_offsets / confidence_power params."""
from __future__ import annotations

import json
import threading

import cv2
import numpy as np
import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.mocap.detect.landmark_offsets import OFFSETS_FILE, body_axes, fit_point_offsets, load_mediapipe_offsets
from tbha_graph.mocap.detect.left_right import GROUPS, apply_sides, consistent_sides, mirror_pairs
from tbha_graph.mocap.detect.mediapipe_pose import prefetched_rgb_frames
from tbha_graph.mocap.io.keypoint_layouts import MEDIAPIPE_POSE
from tbha_graph.mocap.io.video import iter_frames, probe_video
from tbha_graph.mocap.reconstruct.solve_take import SolveTakeParams, point_offsets_of
from tbha_graph.mocap.skeleton import JOINT_NAMES

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TRUTH = ROOT / "data" / "sample" / "ground_truth.npz"


def _landmarks_walking(n=120, seed=0):
    """33 image landmarks (px) of a figure facing the camera that sways and moves its limbs smoothly:
    the person's left on the image's right."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 30.0
    base = np.zeros((n, MEDIAPIPE_POSE.size, 2))
    cx = 320 + 40 * np.sin(0.7 * t)
    for name in MEDIAPIPE_POSE.landmarks:
        k = MEDIAPIPE_POSE.index(name)
        side = 1.0 if ("left" in name) else (-1.0 if "right" in name else 0.0)
        part = name.split("_", 1)[-1]
        width = {"shoulder": 40, "elbow": 70, "wrist": 95, "pinky": 100, "index": 102, "thumb": 98, "hip": 22, "knee": 25,
                 "ankle": 27, "heel": 26, "foot_index": 30}.get(part, 8)
        height = {"shoulder": 150, "elbow": 190, "wrist": 230, "pinky": 240, "index": 242, "thumb": 238, "hip": 270,
                  "knee": 350, "ankle": 430, "heel": 435, "foot_index": 440}.get(part, 110)
        swing = 12 * np.sin(2.0 * t + (0 if side > 0 else np.pi)) if part not in ("shoulder", "hip") else 0.0
        base[:, k, 0] = cx + side * width + swing
        base[:, k, 1] = height + 0.3 * swing
    return base + rng.normal(0, 1.0, base.shape)


def _swap_stretches(lm, stretches, groups=GROUPS):
    n = lm.shape[0]
    truth = {g: np.zeros(n, bool) for g in GROUPS}
    for g in groups:
        for a, b in stretches:
            truth[g][a:b] = True
    return apply_sides(lm, truth), truth


def test_swapped_stretches_are_swapped_back():
    lm = _landmarks_walking()
    # a detector that takes the person to face away in stretches (the T-pose start included), limb groups apart
    bad, truth = _swap_stretches(lm, [(0, 30), (55, 70)])
    truth["legs"][90:100] = ~truth["legs"][90:100]
    bad = apply_sides(bad, {"legs": np.isin(np.arange(len(lm)), np.arange(90, 100))})
    got = consistent_sides(bad, np.ones(len(lm), bool))
    for g in GROUPS:
        np.testing.assert_array_equal(got[g], truth[g], err_msg=g)
    np.testing.assert_allclose(apply_sides(bad, got), lm)
    # the detector's own labels as the start: the same path up to the first frame's choice
    det = consistent_sides(bad, np.ones(len(lm), bool), start="detector")
    assert not det["arms"][0] and (det["arms"] != truth["arms"]).all()


def test_a_reference_that_knows_the_sides_decides_them_where_the_opening_would_not():
    """A take seen from behind all along: the detector labels the figure as facing the camera (its left on the
    image's right) and flips for ten frames in the middle. A suit tracker that knows the limbs' sides on the first
    and last 20 frames makes every frame right; without it the opening's facing-the-camera rule makes every frame
    wrong (but the ten flipped ones)."""
    seen = _landmarks_walking()  # where each landmark is in the image, labelled as facing the camera
    n = len(seen)
    wrong_all = {g: np.ones(n, bool) for g in ("arms", "legs")}
    truth = apply_sides(seen, wrong_all)  # the figure faces away: its left is on the image's left
    flip = {g: (np.arange(n) >= 50) & (np.arange(n) < 60) for g in ("arms", "legs")}
    detector = apply_sides(seen, flip)
    reference = np.full_like(truth, np.nan)
    limbs = [MEDIAPIPE_POSE.index(f"{side}_{part}") for side in ("left", "right")
             for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")]
    for rows in (slice(0, 20), slice(n - 20, n)):
        reference[rows, limbs] = truth[rows, limbs] + np.random.default_rng(2).normal(0, 3.0, truth[rows, limbs].shape)
    got = consistent_sides(detector, np.ones(n, bool), reference=reference)
    for g in ("arms", "legs"):
        np.testing.assert_array_equal(got[g], wrong_all[g] ^ flip[g], err_msg=g)
    np.testing.assert_allclose(apply_sides(detector, {g: got[g] for g in ("arms", "legs")})[:, limbs], truth[:, limbs])
    alone = consistent_sides(detector, np.ones(n, bool))
    assert not alone["arms"][:50].any() and not alone["legs"][:50].any()
    blind = consistent_sides(detector, np.ones(n, bool), reference=np.full_like(truth, np.nan))  # knows nothing:
    assert all((blind[g] == alone[g]).all() for g in ("arms", "legs"))  # the opening's rule, as without one


def _landmarks_turning(n=120, turn=(45, 75), seed=3):
    """33 image landmarks (px) of a figure that faces the camera, turns its back to it through side-on over the
    frames ``turn`` and walks on facing away, as a camera above the floor sees it: each left/right pair sits at
    ``cos(heading)`` of its width from the body's centre line (the person's left on the image's right while
    facing the camera, on its left once turned), and the toes lie ``20 cos(heading)`` px below the heels (above
    them from behind). Returns the landmarks with the true labels and the detector's, which always puts the
    person's left on the image's right (taking the figure to face the camera all along)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    c = np.cos(np.pi * np.clip((t - turn[0]) / (turn[1] - turn[0]), 0.0, 1.0))  # 1 facing -> -1 away
    cx = 320 + 0.5 * t
    true = np.zeros((n, MEDIAPIPE_POSE.size, 2))
    seen = np.zeros_like(true)
    for name in MEDIAPIPE_POSE.landmarks:
        k = MEDIAPIPE_POSE.index(name)
        side = 1.0 if "left" in name else (-1.0 if "right" in name else 0.0)
        part = name.split("_", 1)[-1]
        width = {"shoulder": 40, "elbow": 60, "wrist": 70, "hip": 22, "knee": 24, "ankle": 25, "heel": 25,
                 "foot_index": 25}.get(part, 8)
        height = {"shoulder": 150, "elbow": 190, "wrist": 230, "hip": 270, "knee": 350, "ankle": 430, "heel": 435,
                  "foot_index": 435}.get(part, 110)
        true[:, k, 0] = cx + side * width * c
        seen[:, k, 0] = cx + side * width * np.abs(c)
        true[:, k, 1] = seen[:, k, 1] = height + (20.0 * c if part == "foot_index" else 0.0)
    noise = rng.normal(0, 0.5, true.shape)
    return true + noise, seen + noise


def test_the_feet_tell_a_turn_to_the_back_from_a_detector_that_keeps_the_figure_facing_the_camera():
    """Continuity alone cannot see the turn: the detector's labels bounce off the centre line where the true
    ones cross it, moving as little. The toes above the heels after the turn make the labels turn with the
    figure; with the feet's cue off they stay as the detector gave them."""
    from tbha_graph.mocap.detect.left_right import feet_facing_cost

    true, seen = _landmarks_turning()
    n = len(true)
    got = consistent_sides(seen, np.ones(n, bool))
    limbs = [MEDIAPIPE_POSE.index(f"{side}_{part}") for side in ("left", "right")
             for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")]
    fixed = apply_sides(seen, {g: got[g] for g in ("arms", "legs")})
    off = np.abs(fixed[:, limbs] - true[:, limbs]).max(axis=(1, 2))
    assert off.max() < 3.0  # measured 0.0 (the same noise on both): every frame's labels as the figure's
    assert got["arms"][80:].all() and got["legs"][80:].all() and not got["arms"][:40].any()
    blind = consistent_sides(seen, np.ones(n, bool), feet_weight=0.0)
    for g in ("arms", "legs"):  # the detector's labels, wrong after the turn (side-on, frame 60, either way)
        assert not blind[g][:55].any() and not blind[g][65:].any(), g
    # the cue itself: nothing side-on or without feet in the layout; facing the camera costs the swapped states
    cost = feet_facing_cost(seen, MEDIAPIPE_POSE)
    assert cost.shape == (n, 4) and (cost.min(axis=1) == 0).all()
    assert cost[10, 3] > 0 and cost[10, 0] == 0 and cost[110, 0] > 0 and cost[110, 3] == 0
    assert np.abs(cost[60]).max() < 0.2 * np.abs(cost[10]).max()
    assert feet_facing_cost(seen, MEDIAPIPE_POSE, weight=0.0) is None
    # toes a few pixels off the heels (a stride, a camera at hip height) are inside the dead zone: no cost
    flat = seen.copy()
    for k in ("left_foot_index", "right_foot_index"):
        flat[:, MEDIAPIPE_POSE.index(k), 1] = flat[:, MEDIAPIPE_POSE.index("left_heel"), 1] + 6.0  # 5 % of the 120 px torso
    assert (feet_facing_cost(flat, MEDIAPIPE_POSE) == 0).all()


def test_undetected_frames_are_skipped_and_pairs_cover_every_side():
    lm = _landmarks_walking()
    bad, truth = _swap_stretches(lm, [(40, 80)])
    detected = np.ones(len(lm), bool)
    detected[35:45] = False
    bad[35:45] = np.nan
    got = consistent_sides(bad, detected)
    np.testing.assert_array_equal(got["arms"][detected], truth["arms"][detected])
    pairs = [i for g in mirror_pairs(MEDIAPIPE_POSE).values() for p in g for i in p]
    sided = [MEDIAPIPE_POSE.index(n) for n in MEDIAPIPE_POSE.landmarks if "left" in n or "right" in n]
    assert sorted(pairs) == sorted(sided)  # every left/right landmark belongs to exactly one pair


def test_offsets_fit_recovers_known_offsets_through_a_camera():
    with np.load(TRUTH) as z:
        P, K = z["joints3d_cam"], z["K"]
    true = np.zeros((16, 2))
    true[:, 0] = np.linspace(-0.03, 0.03, 16)
    true[:, 1] = np.linspace(0.04, -0.02, 16)
    for j, n in enumerate(JOINT_NAMES):  # mirror symmetric, as the fit assumes
        if n.startswith("right_"):
            true[j] = true[JOINT_NAMES.index(n.replace("right_", "left_"))]
    axis, out = body_axes(P)
    X = P + true[None, :, 0:1] * axis + true[None, :, 1:2] * out
    uv = X[..., :2] / X[..., 2:3] * K[0, 0] + K[:2, 2]
    rng = np.random.default_rng(1)
    obs = uv + rng.normal(0, 0.5, uv.shape)
    obs[::17, 5] += 40.0  # outliers are dropped
    got, stats = fit_point_offsets([P], [K], [obs], [np.ones(obs.shape[:2], bool)])
    np.testing.assert_allclose(got[:, 0], true[:, 0], atol=0.004)  # along: well seen
    np.testing.assert_allclose(got[:, 1], true[:, 1], atol=0.02)   # out: mostly along the line of sight here
    assert all(stats[n]["px_median_after"] < 0.6 for n in JOINT_NAMES)


def test_shipped_offsets_table_loads_and_says_how_it_was_fitted(tmp_path):
    offs = load_mediapipe_offsets()
    assert offs.shape == (16, 2) and np.abs(offs).max() < 0.1
    doc = json.loads(OFFSETS_FILE.read_text())
    assert {"how", "command", "renders", "fitted", "residual_px_median_per_axis"} <= set(doc)
    assert len(doc["renders"]) >= 3 and all(r["frames"] > 30 for r in doc["renders"])
    with pytest.raises(NodeError, match="missing"):
        load_mediapipe_offsets(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"offsets_m": {"hips": {"along": 0.0}}}))
    with pytest.raises(NodeError, match="not a landmark offsets table"):
        load_mediapipe_offsets(bad)


def test_solver_point_offsets_param_and_tracks_offsets():
    assert np.count_nonzero(point_offsets_of(SolveTakeParams(points="joints"))) == 0
    rows = np.full((16, 2), 0.01).tolist()
    np.testing.assert_allclose(point_offsets_of(SolveTakeParams(points="joints", point_offsets=rows)), 0.01)
    with pytest.raises(NodeError, match="16 rows"):
        point_offsets_of(SolveTakeParams(points="joints", point_offsets=rows[:3]))
    with pytest.raises(NodeError, match="within 0.3 m"):
        point_offsets_of(SolveTakeParams(points="joints", point_offsets=[[0.5, 0.0]] * 16))


def _video(tmp_path, n=12):
    path = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    for i in range(n):
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, :, 0] = 20 * i  # blue channel encodes the frame
        w.write(img)
    w.release()
    return probe_video(path)


@pytest.mark.parametrize("depth", [0, 1, 4])
def test_reader_thread_gives_the_frames_in_order_as_rgb(tmp_path, depth):
    clip = _video(tmp_path)
    ref = [(i, f[..., ::-1]) for i, f in iter_frames(clip)]
    got = list(prefetched_rgb_frames(clip, depth))
    assert [i for i, _ in got] == [i for i, _ in ref]
    for (_, a), (_, b) in zip(got, ref):
        np.testing.assert_array_equal(a, b)


def test_reader_thread_raises_decoding_errors_and_stops_when_closed(tmp_path):
    clip = _video(tmp_path)
    gen = prefetched_rgb_frames(clip, 2)
    next(gen)
    gen.close()  # the consumer stops early: the reader must not hang on a full queue
    assert not [t for t in threading.enumerate() if t.name == "mediapipe-reader"]
    Path(clip.path).unlink()
    with pytest.raises(NodeError, match="does not exist"):
        list(prefetched_rgb_frames(clip, 2))


def test_undetected_runs_followed_by_a_detection_are_the_ones_backfilled():
    from tbha_graph.mocap.detect.mediapipe_pose import _undetected_runs

    img = np.zeros((12, 33, 4))
    img[[0, 1, 2, 5, 10, 11]] = np.nan  # 0-2 before the first detection, 5 a gap, 10-11 at the end (nothing after)
    assert _undetected_runs(img) == [(0, 3), (5, 6)]
    assert _undetected_runs(np.zeros((3, 33, 4))) == []



class _PoseContext:
    """What the stand-in Poses share with MediaPipe's: use as a context manager (``with ... as pose``)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


class _TrackingPose(_PoseContext):
    """A stand-in MediaPipe Pose in video mode for the backfill test: frame ``k`` (its blue channel / 10) is found
    when the pose is being tracked (a frame before found it) or newly detected (``k`` not in ``missed``), and lost on
    ``lost`` frames whatever came before."""

    def __init__(self, missed: set, lost: set, fed: list):
        self.missed, self.lost, self.fed, self.tracking = missed, lost, fed, False

    def process(self, rgb):
        k = int(round(rgb[0, 0, 2] / 10.0))
        self.fed.append(k)
        self.tracking = k not in self.lost and (self.tracking or k not in self.missed)
        mark = [type("Landmark", (), {"x": float(k), "y": 0.0, "z": 0.0, "visibility": 1.0})()] * 33
        lms = type("Landmarks", (), {"landmark": mark})() if self.tracking else None
        return type("Result", (), {"pose_landmarks": lms, "pose_world_landmarks": lms})()


@pytest.mark.parametrize("chunk", [1, 3, 32])
def test_frames_backwards_are_the_forward_frames_reversed(tmp_path, monkeypatch, chunk):
    from tbha_graph.mocap.detect import mediapipe_pose as mpp

    clip = _video(tmp_path, n=12)
    monkeypatch.setattr(mpp, "BACKWARDS_CHUNK", chunk)
    forward = dict(prefetched_rgb_frames(clip, 0))
    got = list(mpp.backwards_rgb_frames(clip, 2, 10))
    assert [k for k, _ in got] == list(range(9, 1, -1))
    for k, rgb in got:
        np.testing.assert_array_equal(rgb, forward[k])

def test_backfill_beside_the_parts_tracks_every_missed_run_backwards_once(tmp_path, monkeypatch):
    """Runs a part finds inside itself (frame b found after missed frames [a, b)) are tracked backwards as soon as it
    finds them (Backfill.submit, beside the parts); runs across the cut between parts after the parts, from the
    forward detections alone; a backward tracker that loses the pose stops there."""
    from tbha_graph.mocap.detect import mediapipe_pose as mpp

    path = tmp_path / "v.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    for i in range(24):
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, :, 0] = 10 * i  # blue channel: the frame's number
        w.write(img)
    w.release()
    clip = probe_video(path)
    # part 0 = [0, 12): misses 0-3 (the opening), loses 7 and 11; part 1 = [12, 24) from 10: misses 10-12
    missed, lost, fed = {0, 1, 2, 3, 10, 11, 12}, {7, 11}, []
    monkeypatch.setattr(mpp, "PART_LEAD", 2)
    monkeypatch.setattr(mpp, "BACKWARDS_CHUNK", 3)  # the opening's run read back in two chunks
    monkeypatch.setattr(mpp, "open_pose", lambda *a, **k: _TrackingPose(missed, lost, fed))

    class Ctx:
        def progress(self, it, total=None, desc=""):
            yield from it

    p = mpp.mediapipe_pose.params.model_validate({"threads": 2})
    image, world = np.full((24, 33, 4), np.nan), np.full((24, 33, 4), np.nan)
    backfill = mpp.Backfill(None, clip, p, image, world)
    try:
        mpp.run_parts(Ctx(), None, clip, p, [(0, 12), (12, 24)], image, world, on_missed=backfill.submit)
        assert set(backfill.started) == {(0, 4), (7, 8)}  # inside part 0; [11, 13) crosses the cut
        filled = backfill.finish()
    finally:
        backfill.close()
    found = np.flatnonzero(~np.isnan(image).all(axis=(1, 2)))
    # 0-3 tracked back from 4; 7 lost again going back from 8; 12 tracked back from 13, then 11 lost
    assert found.tolist() == [k for k in range(24) if k not in (7, 11)] and filled == 5
    np.testing.assert_array_equal(image[found, 0, 0], found)  # each frame's own landmarks
    # frame b, then b-1 ... down to a (or to where the pose was lost), for each run
    assert fed.count(4) == 2 and fed.count(8) == 2 and fed.count(13) == 2 and fed.count(12) == 2
    assert fed.count(11) == 3  # part 0, part 1's lead, and going back from 13
    fed.clear()  # a run abandoned (Backfill.close on an error or a cancelled run) stops at its next frame
    stop = threading.Event()
    stop.set()
    assert mpp._backfill_run(None, clip, p, 0, 4, image, world, stop) == [] and fed == []


class _FakePose(_PoseContext):
    """Stands in for a MediaPipe Pose in the threading tests of ``run_parts``: records the frames it is fed (the blue
    channel encodes each frame's number, see ``_video``) and raises on frame ``fail_at``."""

    def __init__(self, fed: list, fail_at: int | None):
        self.fed, self.fail_at = fed, fail_at

    def process(self, rgb):
        k = int(round(rgb[0, 0, 2] / 20.0))
        if k == self.fail_at:
            raise ValueError(f"broken at frame {k}")
        self.fed.append((threading.get_ident(), k))
        return type("Result", (), {"pose_landmarks": None, "pose_world_landmarks": None})()


@pytest.mark.parametrize("threads", [1, 2])
def test_run_parts_feeds_each_part_its_frames_and_raises_a_part_s_error(tmp_path, monkeypatch, threads):
    """run_parts (detect.mediapipe_pose's threads): each part gets its own Pose fed its own frames, a part after the
    first from PART_LEAD frames early unless the parts are runs; every frame run advances the one progress bar; an
    error in one part is raised to the caller."""
    from tbha_graph.mocap.detect import mediapipe_pose as mpp

    clip = _video(tmp_path, n=12)
    fed: list = []
    monkeypatch.setattr(mpp, "PART_LEAD", 2)
    monkeypatch.setattr(mpp, "open_pose", lambda mp_pose, p, static: _FakePose(fed, None))
    ticks: list = []

    class Ctx:
        def progress(self, it, total=None, desc=""):
            for item in it:
                ticks.append(item)
                yield item

    p = mpp.mediapipe_pose.params.model_validate({"threads": threads})
    image, world = np.full((12, 33, 4), np.nan), np.full((12, 33, 4), np.nan)
    mpp.run_parts(Ctx(), None, clip, p, [(0, 6), (6, 12)], image, world)
    frames = sorted(k for _, k in fed)
    assert frames == sorted(list(range(12)) + [4, 5]) and len(ticks) == 12  # the second part from frame 4, its lead not counted
    assert len({t for t, _ in fed}) == threads
    fed.clear()
    mpp.run_parts(Ctx(), None, clip, p, [(0, 3), (8, 12)], image, world, runs_given=True)
    assert sorted(k for _, k in fed) == [0, 1, 2, 8, 9, 10, 11]  # runs: no lead
    monkeypatch.setattr(mpp, "open_pose", lambda mp_pose, p, static: _FakePose(fed, 9))
    with pytest.raises(ValueError, match="frame 9"):
        mpp.run_parts(Ctx(), None, clip, p, [(0, 6), (6, 12)], image, world)
