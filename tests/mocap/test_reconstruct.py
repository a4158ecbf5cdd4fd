"""3D reconstruction: bone lengths, the seed's ray-sphere expansion, windowed least squares.

Ground truth: CMU 131_02 mapped to the 16 joints, preceded by a T-pose lead-in (the take's start the
method needs), projected with a known camera. The clip's chest-hips distance varies by ~0.2 mm (a spine
joint the 16-joint model lacks); the lower body is shifted to make it rigid so "exact 2D, true bones"
really is exact.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.calibrate.tsai_coplanar import tsai_coplanar
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.body import body_lengths, lengths_to_body, tpose_on_floor
from tbha_graph.mocap.reconstruct.bone_lengths import bone_lengths
from tbha_graph.mocap.reconstruct.lead_in import tpose_lead_in
from tbha_graph.mocap.reconstruct.ray_sphere import EXPANSION, ray_sphere, solve_ray_sphere
from tbha_graph.mocap.reconstruct.sequence_lsq import SequenceLsqParams, WindowProblem, sequence_lsq
from tbha_graph.mocap.skeleton import (
    DEFAULT_BONE_LENGTHS,
    JOINT_INDEX,
    JOINT_NAMES,
    TPOSE_DIRECTIONS,
    TRIANGLE_JOINTS,
    measure_bone_lengths,
)

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
W, H, F, FPS = 640, 480, 800.0, 120.0
LOWER = [JOINT_INDEX[n] for n in ("hips", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")]


def rigid_cmu(n_frames: int, model_torso: bool = True) -> np.ndarray:
    """``(30 + 90 + n_frames, 16, 3)`` metres: T-pose lead-in + the first ``n_frames`` of CMU 131_02.

    ``model_torso``: place the shoulders where the body model puts them relative to the chest (the clip's
    are 2-4 mm asymmetric), moving each arm with its shoulder, so the calibrators' T-pose model is exact.
    """
    from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh

    J = motion16_from_bvh(CLIP)["joints"][:n_frames].copy()
    chest, hips = JOINT_INDEX["chest"], JOINT_INDEX["hips"]
    v = J[:, hips] - J[:, chest]
    J[:, LOWER] += (v * (np.linalg.norm(v[0]) / np.linalg.norm(v, axis=1, keepdims=True) - 1.0))[:, None]
    if model_torso:
        ls, rs = JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]
        x = J[:, ls] - J[:, rs]
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        mid = 0.5 * (J[:, ls] + J[:, rs]) - J[:, chest]
        y = mid - np.sum(mid * x, axis=1, keepdims=True) * x
        y /= np.linalg.norm(y, axis=1, keepdims=True)
        L = measure_bone_lengths(J[0])
        for side, arm in ((ls, ("left_shoulder", "left_elbow", "left_wrist")), (rs, ("right_shoulder", "right_elbow", "right_wrist"))):
            dx, dy = TPOSE_DIRECTIONS[side, :2]
            new = J[:, chest] + L[side] * (dx * x + dy * y)
            J[:, [JOINT_INDEX[a] for a in arm]] += (new - J[:, side])[:, None]
    return tpose_lead_in(J, hold=30, blend=90)


def camera_for(J: np.ndarray, dx: float = 0.0) -> Camera:
    """Camera 4.5 m in front of the start, at chest height, looking at the middle of the path (``dx``: aim aside)."""
    mid = J[:, 0].mean(axis=0)
    return Camera.look_at((mid[0], 1.3, J[0, 0, 2] + 4.5), (mid[0] + dx, 1.0, mid[2]), focal_px=F, width=W, height=H)


def tracks(px: np.ndarray, tracked: np.ndarray | None = None) -> dict:
    return {"points": px, "tracked": np.ones(px.shape[:2], bool) if tracked is None else tracked,
            "fps": np.array(FPS), "width": np.array(W), "height": np.array(H)}


def mpjpe_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1000.0)


@pytest.fixture(scope="module")
def take():
    J = rigid_cmu(360)
    cam = camera_for(J)
    px = cam.project(J)
    assert cam.in_image(px).all()
    return J, cam, px, lengths_to_body(measure_bone_lengths(J[0]))


def test_expansion_is_centre_out_and_complete():
    known = {JOINT_INDEX[j] for j in TRIANGLE_JOINTS}
    for j, a in EXPANSION:
        assert a in known and j not in known
        known.add(j)
    assert known == set(range(16))
    assert dict(EXPANSION)[JOINT_INDEX["hips"]] == JOINT_INDEX["chest"]


def test_ray_sphere_exact_2d_true_camera_is_exact(take):
    J, cam, px, body = take
    out = run_node(ray_sphere, {"continuity": "velocity"}, tracks=tracks(px), camera=cam.to_model(), body=body)
    err = mpjpe_mm(out["motion"]["joints"], J)
    seed = run_node(ray_sphere, {}, tracks=tracks(px), camera=cam.to_model(), body=body)
    err_seed = mpjpe_mm(seed["motion"]["joints"], J)
    print(f"ray_sphere exact 2D, true camera: MPJPE {err:.3g} mm (velocity rule), {err_seed:.1f} mm (seed's previous-position rule)")
    assert err < 8e-5  # measured 5.4e-5 mm: rounding only
    assert err_seed >= err  # the seed's rule follows the mirror branch after a limb crosses the tangent
    rep = out["report"]
    assert rep["frames"] == len(J) and rep["plane_z_m"] == pytest.approx(J[0, 1, 2], abs=1e-6)
    assert rep["two_roots_left_elbow"] > 0 and rep["triangle_residual_max_m"] < 1e-5
    assert out["motion"]["joints"].shape == J.shape and float(out["motion"]["fps"]) == FPS


def test_ray_sphere_with_noise_stays_on_rays_and_reports_accuracy(take):
    J, cam, px, body = take
    noisy = px + np.random.default_rng(1).normal(0.0, 1.0, px.shape)
    errs = {}
    for rule in ("previous", "velocity"):
        out = run_node(ray_sphere, {"continuity": rule}, tracks=tracks(noisy), camera=cam.to_model(), body=body)
        P = out["motion"]["joints"]
        errs[rule] = mpjpe_mm(P, J)
        # every joint lies on its camera ray (reprojects onto its 2D point) ...
        assert np.abs(cam.project(P) - noisy).max() < 1e-6
        # ... at its bone length from its anchor, or farther where the bone had to be lengthened (no root);
        # the shoulders are the triangle's, whose sides are measured on the first frame
        expanded = [j for j in range(1, 16) if JOINT_NAMES[j] not in TRIANGLE_JOINTS]
        d = measure_bone_lengths(P)[:, expanded] - body_lengths(body)[expanded]
        assert d.min() > -1e-6
        assert 0 < (d > 1e-6).sum() <= out["report"]["no_root_total"]
    # The seed's per-frame method has no redundancy: 1 px of noise moves near-tangent limbs and the
    # near-frontal triangle by decimetres and flips branches (figures in the report to the lead).
    print(f"ray_sphere 1 px noise, true camera: MPJPE {errs['previous']:.1f} mm (seed rule), {errs['velocity']:.1f} mm (velocity)")
    assert max(errs.values()) < 900.0  # measured 577 mm (seed rule) and 606 mm (velocity)


def test_ray_sphere_with_tsai_camera(take):
    J, _, _, body = take
    cam = camera_for(J, dx=0.7)  # actor off the image centre: the 5-point Tsai needs it
    px = cam.project(J)
    assert cam.in_image(px).all()
    calib = run_node(tsai_coplanar, {}, tracks=tracks(px), body=body)
    tcam = calib["camera"].camera()
    assert tcam.K[0, 0] == pytest.approx(F, rel=1e-12)  # measured 1.4e-13: exact 2D gives the exact focal length
    out = run_node(ray_sphere, {"continuity": "velocity"}, tracks=tracks(px), camera=calib["camera"], body=body)
    assert out["report"]["plane_z_m"] == pytest.approx(0.0, abs=1e-6)  # the Tsai world's torso plane
    # compare in each camera's frame (the Tsai world is the actor's T-pose frame, not the data's) ...
    err = mpjpe_mm(tcam.to_camera(out["motion"]["joints"]), cam.to_camera(J))
    # ... and in the Tsai world: the T-pose stands on the plane z = 0, hips above the origin, facing +z
    first = out["motion"]["joints"][0]
    assert np.abs(first[:, 2]).max() < 1e-6 and np.abs(first[0, [0, 2]]).max() < 1e-6
    assert first[JOINT_INDEX["left_wrist"], 0] > 0.5 > -0.5 > first[JOINT_INDEX["right_wrist"], 0]
    print(f"ray_sphere exact 2D, Tsai 5-point camera: MPJPE {err:.3g} mm")
    assert err < 8e-5  # measured 5.4e-5 mm


def test_no_root_lengthens_bone_and_counts():
    rest = tpose_on_floor(body_lengths(None))
    cam = Camera.look_at((0.3, 1.3, 4.5), (0.0, 1.0, 0.0), focal_px=F, width=W, height=H)
    J = np.repeat(rest[None], 3, axis=0)
    J[1:, JOINT_INDEX["left_wrist"], 2] += [0.05, 0.1]  # forearm tilted towards the camera
    lengths = measure_bone_lengths(J[0])
    short = lengths.copy()
    short[JOINT_INDEX["left_wrist"]] *= 0.9  # the user's forearm is too short for what the image shows
    P, stats = solve_ray_sphere(cam.project(J), cam, short, continuity="velocity")
    wrist, elbow = JOINT_INDEX["left_wrist"], JOINT_INDEX["left_elbow"]
    assert stats.no_root["left_wrist"] == 3 and stats.max_lengthening_m["left_wrist"] > 0
    assert sum(v for k, v in stats.no_root.items() if k != "left_wrist") == 0
    # the wrist stays on its ray (reprojects onto its 2D point) at more than the given bone length
    assert np.allclose(cam.project_camera(P[:, wrist]), cam.project(J[:, wrist]), atol=1e-6)
    assert (np.linalg.norm(P[:, wrist] - P[:, elbow], axis=1) > short[wrist]).all()


def test_untracked_joints_are_reconstructed_and_marked(take):
    J, cam, px, body = take
    tracked = np.ones(px.shape[:2], bool)
    tracked[200:220, JOINT_INDEX["right_wrist"]] = False
    out = run_node(ray_sphere, {"continuity": "velocity"}, tracks=tracks(px, tracked), camera=cam.to_model(), body=body)
    assert (out["motion"]["tracked"] == tracked).all()
    assert mpjpe_mm(out["motion"]["joints"][200:220], J[200:220]) < 6e-9  # measured 4.0e-9 mm: exact 2D is used untracked too


def test_ray_sphere_refuses_mismatched_image_size(take):
    J, cam, px, body = take
    tr = tracks(px)
    tr["width"] = np.array(1280)
    with pytest.raises(NodeError, match="1280x480"):
        run_node(ray_sphere, {}, tracks=tr, camera=cam.to_model(), body=body)
    with pytest.raises(NodeError, match="did you mean 'left_elbow'"):
        run_node(ray_sphere, {}, tracks=tracks(px), camera=cam.to_model(), body={"left_elbw": 0.3})


def test_sequence_lsq_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    m = 4
    obs = rng.normal(0.0, 0.1, (m, 16, 2))
    prob = WindowProblem(obs, np.ones((m, 16)), F, np.full(16, 0.3), 1.0, 0.005, 0.002, 4.0)
    x = np.concatenate([obs + rng.normal(0, 0.01, obs.shape), 4.0 + rng.normal(0, 0.2, (m, 16, 1))], axis=-1).ravel()
    h = 1e-6
    num = np.stack([(prob.residuals(x + h * e) - prob.residuals(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=1)
    ana = prob.jac(x).toarray()
    assert np.abs(ana - num).max() < 1e-4 * np.abs(num).max()


def test_sequence_lsq_beats_ray_sphere_on_noisy_2d(take):
    J, cam, px, body = take
    J, px = J[:200], px[:200]  # T-pose lead-in + 2/3 s of walking: keeps the test fast
    noisy = px + np.random.default_rng(2).normal(0.0, 1.0, px.shape)
    seed = run_node(ray_sphere, {}, tracks=tracks(noisy), camera=cam.to_model(), body=body)
    lsq = run_node(sequence_lsq, {}, tracks=tracks(noisy), camera=cam.to_model(), body=body)
    e_seed, e_lsq = mpjpe_mm(seed["motion"]["joints"], J), mpjpe_mm(lsq["motion"]["joints"], J)
    print(f"1 px noise: ray_sphere (seed) MPJPE {e_seed:.1f} mm, sequence_lsq {e_lsq:.1f} mm; report {lsq['report']}")
    assert e_lsq <= e_seed
    assert lsq["report"]["final_bone_rms_mm"] < seed_bone_rms_mm(seed["motion"]["joints"], body)
    # on exact 2D the least squares keep the exact start (it is the optimum up to the smoothness prior)
    exact = run_node(sequence_lsq, {"init_smoothing": [0.0]}, tracks=tracks(px), camera=cam.to_model(), body=body)
    assert mpjpe_mm(exact["motion"]["joints"], J) < 1.6  # measured 1.10 mm (the smoothness prior's pull)


def seed_bone_rms_mm(joints: np.ndarray, body: dict) -> float:
    L = body_lengths(body)
    d = measure_bone_lengths(joints)[:, 1:] - L[1:]
    return float(np.sqrt(np.mean(d**2)) * 1000.0)


def test_sequence_lsq_params_are_validated():
    with pytest.raises(ValidationError, match=r"overlap \(10\) must be smaller than window \(10\)"):
        SequenceLsqParams(window=10, overlap=10)
    with pytest.raises(ValidationError, match=r"init_smoothing\.0\n  Input should be greater than or equal to 0"):
        SequenceLsqParams(init_smoothing=[-1.0])


# --- bone lengths ------------------------------------------------------------------------------------
def test_bone_lengths_from_partial_file_and_height(tmp_path):
    path = tmp_path / "me.yaml"
    path.write_text("left_knee: 0.45\nright_knee: 0.45\n")
    out = run_node(bone_lengths, {"path": path, "height": 1.9})
    body, defaults = out["body"], run_node(bone_lengths, {"height": 1.9})["body"]
    assert body["left_knee"] == 0.45 and body["right_knee"] == 0.45
    assert body["neck"] == defaults["neck"] > DEFAULT_BONE_LENGTHS["neck"]  # missing bones: defaults scaled up to 1.9 m
    assert out["report"]["method"] == "file" and "neck" in out["report"]["from_defaults"]
    assert set(body) == set(JOINT_NAMES[1:])


def test_bone_lengths_unknown_name_suggests(tmp_path):
    path = tmp_path / "me.yaml"
    path.write_text("left_kne: 0.45\n")
    with pytest.raises(NodeError, match="did you mean 'left_knee'"):
        run_node(bone_lengths, {"path": path})
    path.write_text("left_knee: -3\n")
    with pytest.raises(NodeError, match="left_knee"):
        run_node(bone_lengths, {"path": path})


def test_bone_lengths_estimated_from_tpose(take):
    J, cam, px, body = take
    out = run_node(bone_lengths, {"plane_z": float(J[0, 1, 2]), "symmetric": False}, tracks=tracks(px), camera=cam.to_model())
    got, true = body_lengths(out["body"]), body_lengths(body)
    assert out["report"]["method"] == "tpose"
    assert np.abs(got - true).max() < 1e-6
    # Tsai's world: the T-pose plane is z = 0, found from the ankles on the floor (no plane_z given)
    rest = tpose_on_floor(body_lengths(None))
    tcam = Camera.look_at((0.8, 1.4, 4.5), (0.5, 1.0, 0.0), focal_px=F, width=W, height=H)
    est = run_node(bone_lengths, {}, tracks=tracks(np.repeat(tcam.project(rest)[None], 3, 0)), camera=tcam.to_model())
    assert est["report"]["plane_z_m"] == pytest.approx(0.0, abs=1e-6)
    assert np.abs(body_lengths(est["body"]) - body_lengths(None)).max() < 1e-6
