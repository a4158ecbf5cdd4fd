"""io.ground_truth, evaluate.measures and evaluate.metrics on CMU 131_02 seen by a known camera."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.evaluate import measures as m
from tbha_graph.mocap.evaluate.metrics import metrics
from tbha_graph.mocap.io.ground_truth import ground_truth
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
N = 120  # frames: 2 s of 131_02 at 60 fps
FPS = 60.0
GT_KEYS = {"mpjpe_mm", "mpjpe_root_mm", "pa_mpjpe_mm", "error_2d_px_median", "error_2d_px_p95", "placed_2d_px_median",
           "placed_2d_px_p95", "accel_error_m_s2",
           "per_joint_mpjpe_mm", "truth_jitter_m_s3"}


@pytest.fixture(scope="module")
def scene():
    """Real motion (walk), a camera in front of it, exact tracks and a ground-truth bundle."""
    joints = motion16_from_bvh(CLIP)["joints"][: 2 * N : 2]
    cam = Camera.look_at((0.3, 1.0, 4.5), (0.3, 0.9, -0.6), focal_px=800.0, width=640, height=480)
    pts = cam.project(joints)
    visible = np.ones((N, sk.N_PATCHES), dtype=bool)
    visible[:, 4] = False  # left_elbow's patch hidden all along
    truth = {
        "joints3d_world": joints, "joints3d_cam": cam.to_camera(joints), "joints2d": pts, "patch_visible": visible,
        "K": cam.K, "R": cam.R, "t": cam.t, "fps": np.array(FPS), "width": np.array(640), "height": np.array(480),
        "joint_names": np.array(sk.JOINT_NAMES),
    }
    tracks = {"points": pts.copy(), "tracked": np.ones((N, sk.N_JOINTS), dtype=bool), "fps": np.array(FPS),
              "width": np.array(640), "height": np.array(480)}
    return {"joints": joints, "camera": cam, "truth": truth, "tracks": tracks}


def motion(joints):
    return {"joints": np.asarray(joints, dtype=np.float64), "fps": np.array(FPS)}


def evaluate(scene, joints, truth=None, tracks=None, raw=None, **params):
    out = run_node(metrics, params=params, motion=motion(joints), tracks=tracks or scene["tracks"],
                   camera=scene["camera"].to_model(), truth=scene["truth"] if truth is None else truth, raw_motion=raw)
    return out["metrics"], out["errors"]


# --- measures ------------------------------------------------------------------------------------
def test_similarity_fit_recovers_a_known_transform_and_rigid_keeps_scale(scene):
    x = scene["joints"][:10]
    rot = Rotation.from_euler("yxz", [70, 10, -5], degrees=True).as_matrix()
    y = 1.3 * x @ rot.T + np.array([1.0, -0.2, 3.0])
    s, R, t = m.similarity_fit(x.reshape(1, -1, 3), y.reshape(1, -1, 3))
    assert s[0] == pytest.approx(1.3, rel=1e-9)
    assert np.allclose(R[0], rot, atol=1e-9) and np.allclose(t[0], [1.0, -0.2, 3.0], atol=1e-9)
    s_rigid, _, _ = m.similarity_fit(x.reshape(1, -1, 3), y.reshape(1, -1, 3), scale=False)
    assert s_rigid[0] == 1.0
    # a mirror image is never "aligned" by a reflection: R stays a proper rotation
    _, R_m, _ = m.similarity_fit(x.reshape(1, -1, 3), (x * [-1, 1, 1]).reshape(1, -1, 3))
    assert np.linalg.det(R_m[0]) == pytest.approx(1.0)


def test_similarity_fit_per_frame_ignores_nan_points(scene):
    x = scene["joints"][:5].copy()
    y = x + np.array([0.0, 0.0, 1.0])
    x[2, 7] = np.nan
    s, R, t = m.similarity_fit(x, y)
    assert np.allclose(s, 1.0) and np.allclose(R, np.eye(3), atol=1e-9) and np.allclose(t, [0.0, 0.0, 1.0], atol=1e-9)
    assert np.allclose(m.apply_similarity(x, s, R, t)[2, 8], y[2, 8], atol=1e-9)


def test_jitter_and_bone_cv_known_values():
    t = np.arange(20) / FPS
    j = np.zeros((20, sk.N_JOINTS, 3))
    j[:, :, 0] = (2.0 * t**3)[:, None]  # third derivative 12 m/s^3 everywhere
    assert m.jitter(j, FPS) == pytest.approx(12.0, rel=1e-6)
    assert m.jitter(j[:3], FPS) != m.jitter(j[:3], FPS)  # NaN: too short
    j = np.broadcast_to(sk.tpose(), (4, sk.N_JOINTS, 3)).copy()
    assert np.allclose(m.bone_length_cv(j), 0.0)
    j[:, sk.JOINT_INDEX["left_wrist"]] = j[:, sk.JOINT_INDEX["left_elbow"]] + np.array([[0.2, 0, 0], [0.3, 0, 0], [0.2, 0, 0], [0.3, 0, 0]])
    cv = m.bone_length_cv(j)
    assert cv[sk.JOINT_INDEX["left_wrist"] - 1] == pytest.approx(0.05 / 0.25)
    assert np.count_nonzero(cv) == 1


def test_means_over_no_values_are_nan_and_warn_nothing(no_hidden_warnings):
    """frame_mean, joint_mean and bone_length_cv over slices with no values: NaN, with no warning emitted
    and none hidden (np.nanmean / np.nanstd's figures elsewhere)."""
    e = np.array([[1.0, np.nan, 3.0], [np.nan, np.nan, np.nan], [2.0, np.nan, 6.0]])
    wrist, elbow, knee = (sk.JOINT_INDEX[k] for k in ("left_wrist", "left_elbow", "right_knee"))
    j = np.broadcast_to(sk.tpose(), (4, sk.N_JOINTS, 3)).copy()
    j[:, wrist] = j[:, elbow] + np.array([[0.2, 0, 0], [np.nan, 0, 0], [0.3, 0, 0], [0.25, 0, 0]])
    j[:, knee] = np.nan  # the right thigh and shin never seen
    with no_hidden_warnings():
        frame, joint, cv = m.frame_mean(e), m.joint_mean(e), m.bone_length_cv(j)
    np.testing.assert_array_equal(frame, [2.0, np.nan, 4.0])
    np.testing.assert_array_equal(joint, [1.5, np.nan, 4.5])
    assert cv[wrist - 1] == pytest.approx(np.std([0.2, 0.3, 0.25]) / 0.25, rel=1e-12)
    unseen = [knee - 1, knee]  # the bones ending at the right knee and at its ankle
    assert np.isnan(cv[unseen]).all()
    assert np.count_nonzero(np.delete(cv, unseen + [wrist - 1])) == 0


def test_joint_angles_known_values():
    """A T-pose has straight elbows (0 deg); bending the left forearm up by 90 deg shows as 90 deg at the
    left wrist joint and nowhere else; a rigid rotation of the whole body changes no joint angle."""
    j = np.broadcast_to(sk.tpose(), (2, sk.N_JOINTS, 3)).copy()
    kids = [k for k in range(1, sk.N_JOINTS) if sk.PARENTS[k] > 0]
    at = {sk.JOINT_NAMES[k]: i for i, k in enumerate(kids)}
    assert m.joint_angles(j)[0, at["left_wrist"]] == pytest.approx(0.0, abs=1e-6)
    lw, le = sk.JOINT_INDEX["left_wrist"], sk.JOINT_INDEX["left_elbow"]
    bent = j.copy()
    bent[1, lw] = bent[1, le] + np.array([0.0, np.linalg.norm(j[1, lw] - j[1, le]), 0.0])
    err = m.joint_angle_error(bent, j)
    assert err[1, at["left_wrist"]] == pytest.approx(90.0, abs=1e-6)
    assert np.count_nonzero(err > 1e-6) == 1
    c, s_ = np.cos(0.7), np.sin(0.7)
    rot = j @ np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]]).T + 3.0
    assert np.allclose(m.joint_angle_error(rot, j), 0.0, atol=1e-6)


# --- evaluate.metrics -----------------------------------------------------------------------------
def test_exact_motion_scores_zero(scene):
    res, err = evaluate(scene, scene["joints"])
    assert res["frames"] == N and res["video_fps"] == FPS and res["tracked_pct"] == 100.0
    for k in ("mpjpe_mm", "mpjpe_root_mm", "pa_mpjpe_mm", "joint_angle_err_deg", "accel_error_m_s2", "reprojection_px_median",
              "reprojection_px_p95", "error_2d_px_median", "error_2d_px_p95"):
        assert res[k] == pytest.approx(0.0, abs=1e-3), k
    assert res["alignment_scale"] == pytest.approx(1.0) and res["alignment_rotation_deg"] == pytest.approx(0.0, abs=1e-3)
    assert res["jitter_m_s3"] == res["truth_jitter_m_s3"] > 0
    assert set(res["per_joint_mpjpe_mm"]) == set(sk.JOINT_NAMES)
    assert err["mpjpe_mm"].shape == err["error_2d_px"].shape == err["reprojection_px"].shape == (N,)
    assert np.allclose(err["mpjpe_mm"], 0.0, atol=1e-6)
    json.dumps(res)  # plain JSON


def test_known_offsets_give_known_figures(scene):
    rng = np.random.default_rng(0)
    d = rng.normal(size=(N, sk.N_JOINTS, 3))
    d *= 0.010 / np.linalg.norm(d, axis=-1, keepdims=True)  # exactly 10 mm, random directions
    d[:, 0] = 0.0  # root exact
    res, _ = evaluate(scene, scene["joints"] + d, alignment="none")
    assert res["mpjpe_mm"] == pytest.approx(10.0 * 15 / 16, abs=1e-4)
    assert res["mpjpe_root_mm"] == pytest.approx(10.0 * 15 / 16, abs=1e-4)
    assert res["per_joint_mpjpe_mm"]["hips"] == 0.0 and res["per_joint_mpjpe_mm"]["head"] == pytest.approx(10.0)
    # a pure +10 mm translation: 10 mm in the world without alignment, 0 root-relative and aligned
    shifted = scene["joints"] + np.array([0.0, 0.0, 0.010])
    assert evaluate(scene, shifted, alignment="none")[0]["mpjpe_mm"] == pytest.approx(10.0)
    res, _ = evaluate(scene, shifted)
    assert res["mpjpe_root_mm"] == pytest.approx(0.0, abs=1e-4) and res["mpjpe_mm"] == pytest.approx(0.0, abs=1e-4)
    assert res["alignment_translation_m"] == pytest.approx(0.010, abs=1e-4)


def test_similarity_alignment_removes_a_global_rotation_and_scale(scene):
    rot = Rotation.from_euler("y", 90, degrees=True).as_matrix()
    other_frame = 0.8 * scene["joints"] @ rot.T + np.array([2.0, 0.0, -1.0])  # a calibration's own world frame
    res, _ = evaluate(scene, other_frame, tracks=_tracks_of(scene, scene["joints"]), alignment="similarity")
    assert res["mpjpe_mm"] == pytest.approx(0.0, abs=1e-4)
    assert res["pa_mpjpe_mm"] == pytest.approx(0.0, abs=1e-4)
    assert res["alignment_scale"] == pytest.approx(1 / 0.8) and res["alignment_rotation_deg"] == pytest.approx(90.0)
    rigid, _ = evaluate(scene, other_frame)  # the default headline: one rigid fit, so a wrong scale stays in it
    assert rigid["mpjpe_alignment"] == "rigid" and rigid["alignment_scale"] == 1.0
    assert rigid["mpjpe_mm"] > 50.0  # 20 % too small: a rigid fit keeps that error
    assert rigid["mpjpe_root_mm"] > 100.0  # no alignment at all


def test_noise_in_2d_and_untracked_joints(scene):
    rng = np.random.default_rng(1)
    tracks = dict(scene["tracks"])
    tracks["points"] = scene["tracks"]["points"] + rng.normal(0, 2.0, size=(N, sk.N_JOINTS, 2))
    tracked = np.ones((N, sk.N_JOINTS), dtype=bool)
    tracked[:30, sk.JOINT_INDEX["right_knee"]] = False
    tracks["tracked"] = tracked
    res, err = evaluate(scene, scene["joints"], tracks=tracks)
    assert res["tracked_pct"] == pytest.approx(100 * (1 - 30 / (N * 16)), abs=1e-3)
    # |N(0, 2 I)| in 2D is Rayleigh(2): median 2*sqrt(2 ln 2) = 2.355 px
    assert res["reprojection_px_median"] == pytest.approx(2.355, rel=0.06)
    assert res["error_2d_px_median"] == pytest.approx(2.355, rel=0.06)
    assert res["error_2d_px_p95"] > res["error_2d_px_median"]
    assert np.isfinite(err["error_2d_px"]).all() and (err["error_2d_px"] > 0).all()


def test_hidden_patches_are_left_out_of_the_2d_error(scene):
    tracks = dict(scene["tracks"])
    pts = scene["tracks"]["points"].copy()
    pts[:, sk.JOINT_INDEX["left_elbow"]] += 500.0  # wildly wrong, but the truth says its patch is hidden
    tracks["points"] = pts
    res, _ = evaluate(scene, scene["joints"], tracks=tracks)
    assert res["error_2d_px_p95"] == pytest.approx(0.0, abs=1e-4)
    assert res["reprojection_px_p95"] > 400  # the reprojection check does not know about the truth


def test_points_placed_without_being_tracked_are_scored_apart_from_the_tracked(scene):
    tracks = dict(scene["tracks"])
    pts = scene["tracks"]["points"].copy()
    tracked = np.ones((N, sk.N_JOINTS), dtype=bool)
    knee = sk.JOINT_INDEX["right_knee"]
    tracked[:20, knee] = False
    pts[:20, knee] += 40.0  # the tracker's guess for a patch it did not see (its patch is visible in the truth)
    tracks["points"], tracks["tracked"] = pts, tracked
    res, err = evaluate(scene, scene["joints"], tracks=tracks)
    assert res["error_2d_px_p95"] == pytest.approx(0.0, abs=1e-4)  # the guesses are not tracking errors
    assert res["placed_2d_px_median"] == pytest.approx(40.0 * np.sqrt(2.0), rel=1e-6)
    assert np.nanmax(err["error_2d_px"]) == pytest.approx(0.0, abs=1e-4)
    assert np.isfinite(err["placed_2d_px"][:20]).all() and np.isnan(err["placed_2d_px"][20:]).all()


def test_truth_at_another_resolution_is_rescaled(scene):
    half = {k: v for k, v in scene["tracks"].items()}
    half["points"] = (scene["tracks"]["points"] + 0.5) * 0.5 - 0.5
    half["width"], half["height"] = np.array(320), np.array(240)
    res, _ = evaluate(scene, scene["joints"], tracks=half)
    assert res["error_2d_px_median"] == pytest.approx(0.0, abs=1e-4)


def test_empty_truth_gives_quality_figures_only(scene):
    res, err = evaluate(scene, scene["joints"], truth={})
    assert not GT_KEYS & set(res)
    assert {"frames", "tracked_pct", "reprojection_px_median", "bone_length_cv_pct", "jitter_m_s3"} <= set(res)
    assert np.isnan(err["mpjpe_mm"]).all() and np.isfinite(err["reprojection_px"]).all()
    out = run_node(metrics, motion=motion(scene["joints"]), tracks=scene["tracks"], camera=scene["camera"].to_model())
    assert not GT_KEYS & set(out["metrics"])


def test_raw_motion_shows_what_the_filter_removed(scene):
    rng = np.random.default_rng(2)
    raw = scene["joints"] + rng.normal(0, 0.005, size=scene["joints"].shape)
    res, _ = evaluate(scene, scene["joints"], raw=motion(raw))
    assert res["raw_jitter_m_s3"] > 10 * res["jitter_m_s3"]
    assert res["raw_mpjpe_mm"] > 5.0 and res["mpjpe_mm"] == pytest.approx(0.0, abs=1e-3)


def test_frame_count_mismatch_is_a_clear_error(scene):
    with pytest.raises(NodeError, match="ground truth has 120 frames but the motion has 100"):
        evaluate(scene, scene["joints"][:100], tracks=_tracks_of(scene, scene["joints"][:100]))
    with pytest.raises(ValueError):
        evaluate(scene, scene["joints"], alignment="affine")


def _tracks_of(scene, joints):
    pts = scene["camera"].project(joints)
    return {"points": pts, "tracked": np.ones(pts.shape[:2], dtype=bool), "fps": np.array(FPS)}


# --- io.ground_truth --------------------------------------------------------------------------------
def test_ground_truth_node_reads_slices_and_refuses_bad_files(scene, tmp_path):
    path = tmp_path / "ground_truth.npz"
    np.savez(path, **scene["truth"])
    truth = run_node(ground_truth, params={"path": str(path)})["truth"]
    assert np.array_equal(truth["joints3d_world"], scene["joints"]) and truth["patch_visible"].dtype == bool
    cut = run_node(ground_truth, params={"path": str(path), "start": 10, "stop": 40})["truth"]
    assert cut["joints2d"].shape == (30, 16, 2) and np.array_equal(cut["joints3d_world"], scene["joints"][10:40])
    assert cut["K"].shape == (3, 3)
    assert run_node(ground_truth, params={"path": None})["truth"] == {}
    assert run_node(ground_truth)["truth"] == {}

    bad = tmp_path / "bad.npz"
    np.savez(bad, joints2d=scene["truth"]["joints2d"])
    with pytest.raises(NodeError, match=r"bad\.npz: missing key\(s\) \['joints3d_world', 'fps'\]"):
        run_node(ground_truth, params={"path": str(bad)})
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, joints3d_world=scene["joints"], fps=np.array(FPS), joints2d=np.zeros((N, 15, 2)))
    with pytest.raises(NodeError, match=r"joints2d has shape \(120, 15, 2\), expected \(120, 16, 2\)"):
        run_node(ground_truth, params={"path": str(wrong)})
    junk = tmp_path / "junk.npz"
    junk.write_text("not a zip")
    with pytest.raises(NodeError, match="junk.npz"):
        run_node(ground_truth, params={"path": str(junk)})
    with pytest.raises(NodeError, match="does not exist"):
        run_node(ground_truth, params={"path": str(tmp_path / "missing.npz")})


def test_extra_reports_join_the_metrics_without_overwriting(scene):
    out = run_node(metrics, {}, motion=motion(scene["joints"]), tracks=scene["tracks"], camera=scene["camera"].to_model(),
                   truth=scene["truth"], extra={"foot_sliding_after_mm": 0.2, "frames": -1, "per_joint": {"a": 1}})
    res = out["metrics"]
    assert res["foot_sliding_after_mm"] == 0.2 and res["frames"] == N and "per_joint" not in res


def test_the_solvers_unseen_frames_are_doubtful_in_the_metrics(scene):
    """The solver's ``unseen_ranges`` (nothing of the actor seen) reach ``doubtful_ranges`` as 'not seen' and the
    error plot's per-frame flags; without them no frame is flagged so."""
    args = dict(motion=motion(scene["joints"]), tracks=scene["tracks"], camera=scene["camera"].to_model(), truth=scene["truth"])
    out = run_node(metrics, {}, **args, extra={"unseen_ranges": [[N - 5, N - 1]]})
    assert [r for r in out["metrics"]["doubtful_ranges"] if r[2] == "not seen"] == [[N - 5, N - 1, "not seen"]]
    assert (out["errors"]["doubtful"][N - 5:] > 0).all()
    plain = run_node(metrics, {}, **args, extra={})
    assert not [r for r in plain["metrics"]["doubtful_ranges"] if r[2] == "not seen"]
