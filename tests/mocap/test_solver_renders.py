"""The default pipeline on three CMU clips rendered by the project's renderer with other cameras than the
sample's (``bench/solver_accuracy.py``'s takes: focal 500-1200 px, 0.9-1.8 m high, 5-6 m away, a walk that
turns, a hop, a far walk), scored against the renders' truth as ``metrics.json`` scores it.

With the true focal length given the figures are the solver's own; bounds sit about 1.5x above what was
measured (2026-11-26), so a regression past them is a real loss. With the focal length estimated, it comes
from the room's floor tiles (``calibrate.vanishing_points``), refined by the take; the take alone would
leave it to luck (``bench/solver_diagnosis.py``: five starting grids gave -64..+18 % on these takes).
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tbha_graph.core.cache import Cache
from tbha_graph.core.runner import run_graph

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from solver_accuracy import TAKES, render_graph  # noqa: E402  (one definition of the takes, shared with the bench)

#: take -> (mpjpe_mm, joint_angle_err_deg, floor_penetration_mm) bounds with the focal length given;
#: measured 93.1 / 9.0 / 2.1 (MediaPipe's keypoints and its torso facing where no torso patch is seen), 39.9 / 5.0 /
#: 1.3, 61.4 / 6.4 / 3.8 (2026-11-27, round 16: MediaPipe's left and right taken from the suit's patches and its
#: facing passed to the solver; before it, after the fix of the keypoints' rows in the focal length's column, 143.9 /
#: 11.3 / 2.0 for 131_01, whose body turned the wrong way round while its back was to the camera, and 47.4 / 6.7 /
#: 1.2 for the hop; 131_02 never loses its torso). The hop's figure is the search's luck within about 38-51 mm
#: (``bench/solver_sweep.py --repeats 5``, focal from the room)
GIVEN_BOUNDS = {
    "walk131_01_f500_low": (140.0, 13.5, 3.2),
    "hop131_03_f1000_high": (60.0, 7.5, 2.0),
    "walk131_02_f1200_far": (92.0, 9.6, 5.7),
}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return Cache(tmp_path_factory.mktemp("renders-cache"))


def capture(take, cache, focal_given: bool) -> dict:
    return run_graph(render_graph(take, focal_given), outputs=["metrics.json"], cache=cache).output("metrics.json")


@pytest.mark.parametrize("take", TAKES, ids=[t[0] for t in TAKES])
def test_render_given_its_focal_length(take, cache):
    m = capture(take, cache, focal_given=True)
    mpjpe, angle, floor = GIVEN_BOUNDS[take[0]]
    assert m["mpjpe_alignment"] == "rigid" and m["alignment_scale"] == 1
    assert abs(m["focal_err_pct"]) < 0.01
    assert m["mpjpe_mm"] < mpjpe and m["joint_angle_err_deg"] < angle and m["floor_penetration_mm"] < floor
    assert m["foot_skate_mm"] < 4.7  # measured 2.5-3.3 mm per planted frame


#: take -> (|focal error| %, mpjpe mm) bounds with the focal length estimated, and whether the room's lines give it;
#: measured +0.6 % / 82.8 mm, +0.1 % / 38.1 mm, -3.2 % / 59.4 mm, all from the room's lines (2026-11-27, round 16:
#: MediaPipe's facing; before it +3.2 % / 93.7 (81.3 before the keypoint rows' fix), +0.3 % / 38.6, -3.2 % / 59.4;
#: round 14, before the limbs held to the opening T-pose, +3.3 % / 100.6, +0.3 % / 35.5, -3.3 % / 64.4). The mm
#: are the pose search's luck more than the camera's: with sigma_px 1.5 / 2 / 3 they were 86 / 112 / 95, 76 / 36 / 49
#: and 61 / 64 / 67 mm, and the take's refinement moves the hop's focal length within the room's ±6 % (-3.8 % at
#: sigma_px 1), so the bounds sit 1.5x above the worst measured
ESTIMATED_BOUNDS = {
    "walk131_01_f500_low": (3.8, 140.0, True),
    "hop131_03_f1000_high": (5.7, 114.0, True),
    "walk131_02_f1200_far": (4.9, 100.0, True),
}


@pytest.mark.parametrize("take", TAKES, ids=[t[0] for t in TAKES])
def test_render_with_its_focal_length_estimated(take, cache):
    m = capture(take, cache, focal_given=False)
    focal, mpjpe, from_room = ESTIMATED_BOUNDS[take[0]]
    assert m["focal_source"].startswith("room lines") == from_room
    if not from_room:  # the take alone: both said
        assert any("no focal length from the room" in w for w in m["warnings"])
        assert any("focal length is ambiguous" in w for w in m["warnings"])
    assert abs(m["focal_err_pct"]) < focal and m["mpjpe_mm"] < mpjpe
    if take[0] == "walk131_01_f500_low":  # it turns its back: MediaPipe's keypoints placed those frames (measured 39)
        assert 30 <= m["keypoint_frames"] <= 45, m["keypoint_frames"]
    else:  # the others never lose the whole torso (the hop for one frame at most)
        assert m.get("keypoint_frames", 0) <= 1
    if from_room:  # the floor's tilt from the room too: the camera's height right (measured 1.7 / 3.6 / -0.3 cm; from the
        assert abs(m["camera_height_err_m"]) < 0.057  # feet alone -27 / 3.8 / -9.7 cm at sigma_px 1)


def test_limbs_hang_where_only_the_head_is_seen(cache):
    """131_01 turns its back for 34 frames, where the tracker sees the head alone: without the hang prior
    (``sigma_hang``) the limbs flail inside the outline. Measured on those frames, the pose about the hips
    (root-relative joint error), as ``bench/solver_sweep.py`` draws it (the tracks as they are, then twice with
    0.05 px of noise, seeds 1 and 2): 230 mm without it, 204 with it (218 / 261 / 212 against 234 / 226 / 151,
    2026-11-27 round 20). One draw alone can go either way (2026-11-26: 204 against 171; seed 3 today 166 against
    219): the solve is chaotic in its inputs, so the prior is judged on the mean. Judged without the lean search
    (``lean_search``, round 21), as measured: with it on, as the default runs, the same draws gave 197 without the
    prior and 190 with it (219 / 188 / 185 against 228 / 205 / 136), within the draws' spread; re-judging the prior
    beside the lean search is left open."""
    import numpy as np

    from tbha_graph.mocap.body import body_lengths
    from tbha_graph.mocap.bundles.tracks import read_tracks
    from tbha_graph.mocap.reconstruct import solve_take as st

    assert TAKES[0][0] == "walk131_01_f500_low"
    run = run_graph(render_graph(TAKES[0]), outputs=["track", "silhouette", "lens", "render"], cache=cache)
    tr = read_tracks(run.output("track.tracks"))
    n = tr.n_frames
    truth = np.asarray(run.output("render.ground_truth")["joints3d_world"])[:n]
    away = st.facing_away(tr.tracked.astype(float))
    assert away.sum() >= 30
    sil = st.silhouette_field(run.output("silhouette.silhouette"), n)
    lens = run.output("lens.lens")
    errors = np.zeros((2, 3))
    for i, hang in enumerate((None, 1.0)):
        for seed in range(3):
            points = tr.points if seed == 0 else tr.points + np.random.default_rng(seed).normal(0.0, 0.05, tr.points.shape)
            res = st.solve_take_arrays(points, tr.tracked, body_lengths(None), tr.width, tr.height, float(tr.fps),
                                       st.SolveTakeParams(sigma_hang=hang, lean_search=False), silhouette=sil, lens=lens)
            J = res["joints"]
            errors[i, seed] = np.linalg.norm((J - J[:, :1]) - (truth - truth[:, :1]), axis=-1)[away].mean() * 1000
    without, with_hang = errors.mean(axis=1)
    assert with_hang < 0.95 * without and with_hang < 260, errors  # measured 204 against 230 mm
