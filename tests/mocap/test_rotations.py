"""Rotation solvers (rotations.quaternion, rotations.kabsch) and their quaternion math.

Ground truth: CMU clip 131_02 (first 720 frames at 120 fps) mapped onto the 16 joints.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.filter.bone_length import constant_bone_lengths
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh, rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.quat import quat_apply, quat_inv, quat_mul
from tbha_graph.mocap import quat as Q
from tbha_graph.mocap.rotations.kabsch import kabsch_node
from tbha_graph.mocap.rotations.quaternion import quaternion
from tbha_graph.mocap.rotations.rest import HINGES, TORSO

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
SOLVERS = [pytest.param(quaternion, id="quaternion"), pytest.param(kabsch_node, id="kabsch")]
J = sk.JOINT_INDEX


@pytest.fixture(scope="module")
def cmu():
    """CMU 131_02 on the 16 joints with every bone at its median length (metres)."""
    m = motion16_from_bvh(CLIP)
    return {"joints": constant_bone_lengths(m["joints"]), "fps": np.asarray(float(m["fps"]))}


def solve(spec, motion, **params):
    return run_node(spec, params=params, motion=motion)["rotations"]


def fk(rot):
    return forward_kinematics(sk.PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])


def mpjpe_mm(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1000)


def same_rotation(a, b, tol):
    """True where quaternions a and b are the same rotation (q and -q alike)."""
    return np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1)) < tol


# --------------------------------------------------------------------------------------------- math
def test_shortest_arc_maps_a_to_b_including_antiparallel_and_zero():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2000, 3)), rng.normal(size=(2000, 3))
    q = Q.shortest_arc(a, b)
    ua, ub = Q.unit(a)[0], Q.unit(b)[0]
    assert np.abs(quat_apply(q, ua) - ub).max() < 1e-12
    # the angle is the angle between the vectors (shortest arc, no extra twist)
    assert np.allclose(Q.angle_of(q), np.arccos(np.clip(Q.dot(ua, ub), -1, 1)), atol=1e-7)
    anti = Q.shortest_arc(ua, -ua)
    assert np.isfinite(anti).all() and np.abs(quat_apply(anti, ua) + ua).max() < 1e-12
    axis_aligned = Q.shortest_arc(np.array([[0, 1.0, 0]]), np.array([[0, -1.0, 0]]))
    assert np.abs(quat_apply(axis_aligned, [0, 1.0, 0]) - [0, -1.0, 0]).max() < 1e-12
    zero = Q.shortest_arc(np.zeros((3, 3)), ub[:3])
    assert np.array_equal(zero, Q.identity((3,)))


def test_rotation_from_pairs_recovers_random_rotations():
    rng = np.random.default_rng(2)
    truth = Rotation.random(3000, random_state=3)
    u1, u2 = rng.normal(size=(2, 3000, 3))
    for exact_first in (True, False):
        q = Q.rotation_from_pairs(u1, u2, truth.apply(u1), truth.apply(u2), exact_first=exact_first)
        assert same_rotation(q, truth.as_quat(), 1e-9).all()


def test_rotation_from_pairs_degenerate_cases():
    rng = np.random.default_rng(4)
    u1, u2 = rng.normal(size=(2, 500, 3))
    axis = Q.unit(rng.normal(size=(500, 3)))[0]
    # half turns with the axis in the plane of u1, u2: the two bisector planes coincide
    u2c = 0.3 * u1 + axis
    half = Rotation.from_rotvec(np.pi * axis)
    q = Q.rotation_from_pairs(u1, u2c, half.apply(u1), half.apply(u2c))
    assert same_rotation(q, half.as_quat(), 1e-9).all()
    # first pair already aligned: a rotation about u1
    about_u1 = Rotation.from_rotvec(0.8 * Q.unit(u1)[0])
    q = Q.rotation_from_pairs(u1, u2, about_u1.apply(u1), about_u1.apply(u2))
    assert same_rotation(q, about_u1.as_quat(), 1e-9).all()
    # nothing moved
    assert same_rotation(Q.rotation_from_pairs(u1, u2, u1, u2), Q.identity((500,)), 1e-12).all()
    # collinear reference vectors: no twist information, the shortest arc of the first pair
    rot = Rotation.random(500, random_state=5)
    q = Q.rotation_from_pairs(u1, 2 * u1, rot.apply(u1), rot.apply(2 * u1))
    assert same_rotation(q, Q.shortest_arc(u1, rot.apply(u1)), 1e-9).all()
    # zero vectors
    z = np.zeros((500, 3))
    assert np.isfinite(Q.rotation_from_pairs(z, z, u1, u2)).all()


def test_swing_twist_splits_about_axis():
    rng = np.random.default_rng(6)
    q = Rotation.random(2000, random_state=7).as_quat()
    axis = Q.unit(rng.normal(size=(2000, 3)))[0]
    swing, twist = Q.swing_twist(q, axis)
    assert np.abs(quat_mul(swing, twist) - q).max() < 1e-12
    assert np.abs(np.cross(twist[:, :3], axis)).max() < 1e-12  # twist is about the axis
    assert np.abs(Q.dot(swing[:, :3], axis)).max() < 1e-12  # swing axis is perpendicular to it
    # a pure twist is all twist
    pure = Q.from_axis_angle(axis, rng.uniform(-3, 3, 2000))
    assert same_rotation(Q.swing_twist(pure, axis)[1], pure, 1e-12).all()


def test_continuous_removes_sign_flips():
    q = Rotation.from_rotvec(np.linspace(0, 6, 200)[:, None] * [0, 1.0, 0]).as_quat()
    flipped = q * np.where(np.arange(200) % 3 == 0, -1.0, 1.0)[:, None]
    c = Q.continuous(flipped)
    assert np.all(Q.dot(c[1:], c[:-1]) > 0) and same_rotation(c, q, 1e-12).all()


# ------------------------------------------------------------------------------------------- solvers
@pytest.mark.parametrize("spec", SOLVERS)
@pytest.mark.parametrize("torso_rest", ["measured", "tpose"])
def test_tpose_gives_identity(spec, torso_rest):
    pose = np.repeat(sk.tpose()[None], 4, axis=0)
    rot = solve(spec, {"joints": pose, "fps": np.asarray(30.0)}, torso_rest=torso_rest)
    assert np.abs(rot["local_quat"] - [0, 0, 0, 1.0]).max() < 1e-12
    assert np.allclose(rot["offsets"][1:], (sk.bone_lengths_array()[:, None] * sk.TPOSE_DIRECTIONS)[1:], atol=1e-12)
    assert np.allclose(rot["root_position"], pose[:, 0])
    assert np.allclose(fk(rot)[0], pose, atol=1e-12)


@pytest.mark.parametrize("spec", SOLVERS)
def test_cmu_positions_are_reproduced(spec, cmu):
    truth = cmu["joints"]
    swung, _ = fk(solve(spec, cmu, feet_reach=False, torso_fit=False))
    exact, _ = fk(solve(spec, cmu, torso_fit=False))
    rot = solve(spec, cmu)
    pos, _ = fk(rot)
    err, err_exact, err_swung = mpjpe_mm(pos, truth), mpjpe_mm(exact, truth), mpjpe_mm(swung, truth)
    print(f"{spec.type} CMU 131_02 MPJPE {err:.2f} mm; without the torso fit {err_exact:.2f}, {err_swung:.2f} also "
          "without feet_reach")
    # The 16-joint torso is rigid, the actor's is not (lumbar spine bends ~8 deg relative to the pelvis). With the
    # reference vectors matched exactly and every limb bone swung to the clip's direction: measured 6.2 mm
    # (quaternion) and 7.1 mm (kabsch); 3.5 / 4.7 with the knees bent so the ankles land on the clip's
    # (feet_reach); 3.02 for both with the torso fitted by least squares (the default: both reach the same optimum)
    assert err_swung < 9.0
    assert err_exact < (5.2 if spec is quaternion else 7.0)
    assert err < 3.5 and err < err_exact - 0.4
    # swung: every bone below the torso (neck->head, both arms, both legs) is reproduced exactly; with feet_reach
    # the arms and the head still are
    single = [j for j in range(1, 16) if sk.PARENTS[j] not in TORSO]
    upper = [j for j in single if not sk.JOINT_NAMES[j].endswith(("_knee", "_ankle"))]
    for posed, bones in ((swung, single), (exact, upper), (pos, upper)):
        bone = posed[:, bones] - posed[:, sk.PARENTS[bones]]
        bone_truth = truth[:, bones] - truth[:, sk.PARENTS[bones]]
        assert np.abs(bone - bone_truth).max() < 1e-9
    # bone lengths are constant (the offsets) and equal the clip's medians
    assert np.allclose(np.linalg.norm(rot["offsets"], axis=1), np.median(sk.measure_bone_lengths(truth), axis=0), atol=1e-12)


@pytest.mark.parametrize("spec", SOLVERS)
def test_representable_motion_is_reproduced_below_a_micrometre(spec, cmu):
    """Positions a 16-joint skeleton can take (FK of a solution) come back exactly."""
    rigid, _ = fk(solve(spec, cmu))
    again, _ = fk(solve(spec, {"joints": rigid, "fps": cmu["fps"]}))
    assert mpjpe_mm(again, rigid) < 1e-3


def _world_errors_deg(rot, truth_rot, joints):
    """Angle between solved and mocap world rotations per frame, after removing each joint's constant
    rest-pose difference (the two rest poses differ)."""
    _, w = fk(rot)
    _, wt = fk(truth_rot)
    out = {}
    for j in joints:
        d = quat_mul(quat_inv(wt[:, j]), w[:, j])
        c = Rotation.from_quat(d).mean().inv().as_quat()
        out[sk.JOINT_NAMES[j]] = np.degrees(Q.angle_of(quat_mul(d, c)))
    return out


def test_hinge_recovers_upper_arm_and_thigh_twist_of_the_mocap(cmu):
    """Upper arms and thighs have no twist in their two points; the elbow/knee hinge gives it back.

    Compared with the CMU joints' own world rotations (their twist included)."""
    truth = rotations16_from_bvh(CLIP)
    limbs = [h[0] for h in HINGES] + [h[1] for h in HINGES]
    # limb bones swung to the clip's own directions (feet_reach moves the legs' off the rigid pelvis's miss)
    with_hinge = _world_errors_deg(solve(quaternion, cmu, feet_reach=False), truth, limbs)
    without = _world_errors_deg(solve(quaternion, cmu, hinge=False, feet_reach=False), truth, limbs)
    for name in with_hinge:
        print(f"{name}: hinge {with_hinge[name].mean():.2f} deg, shortest arc {without[name].mean():.2f} deg")
        assert with_hinge[name].mean() < 1.0
    assert np.mean([e.mean() for e in without.values()]) > 5.0


@pytest.mark.parametrize("spec", SOLVERS)
def test_elbows_and_knees_rotate_about_one_axis(spec, cmu):
    rot = solve(spec, cmu)
    j = cmu["joints"]
    for upper, mid, end, axis in HINGES:
        u, f = Q.unit(j[:, mid] - j[:, upper])[0], Q.unit(j[:, end] - j[:, mid])[0]
        bend = np.arctan2(np.linalg.norm(np.cross(u, f), axis=-1), Q.dot(u, f))
        rv = Q.rotation_vector(rot["local_quat"][:, mid])
        off_axis = np.linalg.norm(rv - Q.dot(rv, axis)[:, None] * np.asarray(axis), axis=-1)
        bent = bend >= np.deg2rad(10.0)  # the default `straight`
        assert bent.mean() > 0.3  # the clip does bend them
        assert off_axis[bent].max() < 1e-6
        assert np.all(off_axis <= bend + 1e-9)  # nearly straight: off the axis by less than the bend
        # flexion is positive about the hinge axis (hyperextension at most 10 degrees)
        along = Q.dot(rv, axis)
        assert along[bent].min() > -np.deg2rad(10.0) - 1e-9
    strict = solve(spec, cmu, hinge_projection=True)
    for _, mid, _, axis in HINGES:
        rv = Q.rotation_vector(strict["local_quat"][:, mid])
        assert np.abs(rv - Q.dot(rv, axis)[:, None] * np.asarray(axis)).max() < 1e-9


def test_parent_frame_swing_does_not_depend_on_heading(cmu):
    """Turning the whole clip about the vertical changes only the root rotation (swing_frame='parent');
    the seed's literal world-frame swing changes the limbs' local rotations too."""
    turn = Rotation.from_euler("y", 90, degrees=True)
    turned = {"joints": turn.apply(cmu["joints"].reshape(-1, 3)).reshape(cmu["joints"].shape), "fps": cmu["fps"]}
    for frame, invariant in (("parent", True), ("world", False)):
        # the torso's least-squares fit off: its own invariance (to its convergence) is tested on its own
        a = solve(quaternion, cmu, swing_frame=frame, hinge=False, torso_fit=False)["local_quat"][:, 1:]
        b = solve(quaternion, turned, swing_frame=frame, hinge=False, torso_fit=False)["local_quat"][:, 1:]
        assert same_rotation(a, b, 1e-9).all() == invariant


def _degenerate_clip():
    base = sk.tpose()
    frames = [base.copy() for _ in range(6)]
    frames[1][:] = base[0]  # every joint at one point (all bones zero length)
    frames[2][J["left_hip"]] = frames[2][J["right_hip"]] = frames[2][J["hips"]]  # pelvis collapsed
    frames[2][J["chest"]] = frames[2][J["hips"]] + [0, 0.25, 0]
    f3 = frames[3]  # arms folded back onto themselves (anti-parallel forearm), straight knees
    f3[J["left_wrist"]] = f3[J["left_shoulder"]]
    f3[J["right_wrist"]] = f3[J["right_shoulder"]]
    f4 = frames[4]  # torso points collinear: shoulders on the neck line, hips on the spine line
    f4[J["left_shoulder"]] = f4[J["right_shoulder"]] = f4[J["chest"]] + [0, 0.1, 0]
    f4[J["left_hip"]] = f4[J["right_hip"]] = f4[J["hips"]] - [0, 0.1, 0]
    f5 = frames[5]  # upside down: every bone reversed
    f5[:] = base[0] - (base - base[0])
    return np.stack(frames)


@pytest.mark.parametrize("spec", SOLVERS)
@pytest.mark.parametrize("params", [{}, {"hinge": False}, {"swing_frame": "world"}, {"straight": 0.0}, {"torso_rest": "tpose"},
                                    {"feet_reach": False}])
def test_degenerate_input_never_gives_nan(spec, params):
    clip = _degenerate_clip()
    rot = solve(spec, {"joints": clip, "fps": np.asarray(30.0)}, **params)
    for key, value in rot.items():
        assert np.isfinite(value).all(), key
    assert np.allclose(np.linalg.norm(rot["local_quat"], axis=-1), 1.0)
    pos, _ = fk(rot)
    assert np.isfinite(pos).all()
    # where a bone has a direction, the re-posed skeleton points it the same way (limbs and neck; the legs' only
    # when swung: feet_reach bends them to reach the ankles)
    single = [j for j in range(1, 16) if sk.PARENTS[j] not in TORSO
              and (params.get("feet_reach") is False or not sk.JOINT_NAMES[j].endswith(("_knee", "_ankle")))]
    got = Q.unit(pos[:, single] - pos[:, sk.PARENTS[single]])[0]
    want, n = Q.unit(clip[:, single] - clip[:, sk.PARENTS[single]])
    ok = n > 1e-9
    assert np.abs(got - want)[ok].max() < 1e-9


def test_non_finite_input_is_refused_with_the_joint_and_frame():
    clip = np.repeat(sk.tpose()[None], 5, axis=0)
    clip[3, J["left_knee"], 1] = np.nan
    with pytest.raises(NodeError, match=r"left_knee.*frame 3"):
        solve(quaternion, {"joints": clip, "fps": np.asarray(30.0)})
    with pytest.raises(NodeError, match="no frames"):
        solve(kabsch_node, {"joints": np.zeros((0, 16, 3)), "fps": np.asarray(30.0)})


def test_outputs_are_continuous_in_time(cmu):
    q = solve(quaternion, cmu)["local_quat"]
    assert np.all(Q.dot(q[1:], q[:-1]) > 0)


def folding_pelvis(cmu):
    """The clip with its hips joint swinging 3 cm forwards and back of the hip joints' line (three times over the
    clip): a pelvis folding against the spine, as the solver's does, which the rigid torso cannot take."""
    joints = cmu["joints"].copy()
    n = len(joints)
    lateral = joints[:, J["left_hip"]] - joints[:, J["right_hip"]]
    spine = joints[:, J["chest"]] - joints[:, J["hips"]]
    forward = Q.unit(np.cross(lateral, spine))[0]
    joints[:, J["hips"]] += 0.03 * np.sin(np.linspace(0, 6 * np.pi, n))[:, None] * forward
    return {"joints": joints, "fps": cmu["fps"]}


@pytest.mark.parametrize("spec", SOLVERS)
def test_feet_reach_keeps_the_ankles_where_a_folding_pelvis_put_them(spec, cmu):
    """A pelvis that folds against the spine (the hips joint swinging 3 cm forwards and back of the hip joints'
    line, as the solver's does) cannot be posed by the rigid torso. Swung bone by bone, each leg moves by the
    pelvis's miss, the ankle with it; with feet_reach the knee bends so the ankle lands on the motion's wherever the
    leg can reach it, in the motion's own knee plane, and nothing above the hips changes."""
    motion = folding_pelvis(cmu)
    joints = motion["joints"]
    # the torso's least-squares fit off: it would take up most of the pelvis's miss itself (tested below)
    swung, _ = fk(solve(spec, motion, feet_reach=False, torso_fit=False))
    reached_rot = solve(spec, motion, torso_fit=False)
    reached, _ = fk(reached_rot)
    ankles = [J["left_ankle"], J["right_ankle"]]
    miss_swung = np.linalg.norm(swung[:, ankles] - joints[:, ankles], axis=-1)
    miss = np.linalg.norm(reached[:, ankles] - joints[:, ankles], axis=-1)
    # where the leg cannot reach (its hip joint put farther than thigh + shin from the ankle) it misses by the excess
    thigh_shin = np.linalg.norm(reached_rot["offsets"][[J["left_knee"], J["right_knee"]]], axis=-1) + \
        np.linalg.norm(reached_rot["offsets"][ankles], axis=-1)
    excess = np.maximum(np.linalg.norm(joints[:, ankles] - reached[:, [J["left_hip"], J["right_hip"]]], axis=-1) - thigh_shin, 0)
    print(f"{spec.type}: ankle miss swung {miss_swung.mean() * 1000:.1f} mm, reached {miss.mean() * 1000:.3f} mm, "
          f"beyond reach on {(excess > 0).mean() * 100:.1f} % of leg-frames")
    assert miss_swung.mean() > 0.019  # measured 32.8 / 28.6 mm (quaternion / kabsch)
    assert np.all(miss <= excess + 1e-6)  # where the leg cannot reach, it misses by no more than the excess
    assert (excess == 0).all() and miss.max() < 1e-6  # here every leg-frame is within reach: the ankles land exactly
    # the knee bends in the motion's own plane (hip joint as posed, knee, ankle)
    for hip, knee, ankle in (("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle")):
        normal = Q.unit(np.cross(joints[:, J[knee]] - reached[:, J[hip]], joints[:, J[ankle]] - reached[:, J[hip]]))[0]
        assert np.abs(Q.dot(reached[:, J[knee]] - reached[:, J[hip]], normal)).max() < 1e-6
    above = [j for j in range(16) if not sk.JOINT_NAMES[j].endswith(("_hip", "_knee", "_ankle"))]
    assert np.abs(reached[:, above] - swung[:, above]).max() < 1e-12


@pytest.mark.parametrize("spec", SOLVERS)
def test_torso_fit_puts_every_joint_as_close_as_the_rigid_torso_allows(spec, cmu):
    """On a pelvis folding against the spine (:func:`folding_pelvis`) the reference vectors match some torso joints
    exactly and everything below the others carries their miss; the least-squares fit of the hips' position and the
    hips' and chest's rotations (the default) spreads it: every frame's summed squared miss is at most the reference
    rotations', the mean much lower, and the fit does not depend on where the actor faces."""
    motion = folding_pelvis(cmu)
    joints = motion["joints"]
    reference, _ = fk(solve(spec, motion, torso_fit=False))
    fitted, _ = fk(solve(spec, motion))
    print(f"{spec.type}: mean miss {mpjpe_mm(reference, joints):.2f} mm with the reference vectors, "
          f"{mpjpe_mm(fitted, joints):.2f} fitted")
    # measured 6.64 (quaternion) / 9.99 (kabsch) -> 4.03 mm for both (the same optimum)
    assert mpjpe_mm(reference, joints) > 6.0
    assert mpjpe_mm(fitted, joints) < 4.5
    sq = lambda posed: ((posed - joints) ** 2).sum(axis=(1, 2))  # noqa: E731
    assert np.all(sq(fitted) <= sq(reference) + 1e-12)
    # the whole clip turned a quarter about the vertical: the same skeleton, turned
    turn = Rotation.from_euler("y", 90, degrees=True)
    turned = {"joints": turn.apply(joints.reshape(-1, 3)).reshape(joints.shape), "fps": motion["fps"]}
    again, _ = fk(solve(spec, turned))
    back = turn.inv().apply(again.reshape(-1, 3)).reshape(again.shape)
    assert np.abs(back - fitted).max() < 1e-7  # metres; measured 3e-8


def test_torso_fit_in_chunks_of_frames_gives_the_same_skeleton(cmu, monkeypatch):
    """Frames are fitted a chunk at a time (memory flat with the take's length); each frame is its own problem, so
    the chunks change nothing but where each chunk stops iterating."""
    from tbha_graph.mocap.rotations import torso_fit

    motion = folding_pelvis(cmu)
    whole, _ = fk(solve(quaternion, motion))
    monkeypatch.setattr(torso_fit, "CHUNK", 100)  # 720 frames: eight chunks, the last of 20
    chunked, _ = fk(solve(quaternion, motion))
    assert np.abs(chunked - whole).max() < 1e-7  # metres
