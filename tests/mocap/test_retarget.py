"""retarget.bvh_character on real motion (CMU 131_02 through rotations16_from_bvh): scaled and
re-proportioned characters, A-pose rest, bone directions, floor contact, spine distribution, errors.

Every check reads the written BVH back with the project's reader and compares it with forward
kinematics of the input motion, computed here independently of the retargeter.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.io.bvh import bvh_positions, bvh_to_local, read_bvh
from tbha_graph.mocap.io.skeleton_map import axes_matrix, rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.retarget.bvh_character import bvh_character
from tbha_graph.mocap.retarget.make_characters import Bone, to_bvh
from tbha_graph.mocap.io.bvh import write_bvh
from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "data" / "mocap" / "cmu" / "131_02.bvh"
APOSE = REPO / "data" / "characters" / "mixamo_like_apose.bvh"
CHILD = REPO / "data" / "characters" / "child.bvh"
STEP = 8  # every 8th frame of 120 fps: 90 frames at 15 fps
MIXAMO = {n: f"mixamorig:{v}" for n, v in {
    "hips": "Hips", "chest": "Spine2", "neck": "Neck", "head": "Head",
    "left_shoulder": "LeftArm", "left_elbow": "LeftForeArm", "left_wrist": "LeftHand",
    "right_shoulder": "RightArm", "right_elbow": "RightForeArm", "right_wrist": "RightHand",
    "left_hip": "LeftUpLeg", "left_knee": "LeftLeg", "left_ankle": "LeftFoot",
    "right_hip": "RightUpLeg", "right_knee": "RightLeg", "right_ankle": "RightFoot"}.items()}
LIMB_BONES = ["head", "left_elbow", "left_wrist", "right_elbow", "right_wrist", "left_knee", "left_ankle",
              "right_knee", "right_ankle"]
BRANCH_BONES = ["left_shoulder", "right_shoulder", "left_hip", "right_hip"]


@pytest.fixture(scope="module")
def rot() -> dict[str, np.ndarray]:
    r = rotations16_from_bvh(CLIP)
    return {**r, "local_quat": r["local_quat"][::STEP].copy(), "root_position": r["root_position"][::STEP].copy(),
            "fps": np.asarray(120.0 / STEP)}


@pytest.fixture(scope="module")
def src(rot) -> np.ndarray:
    return forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])[0]


def retarget(rot, tmp_path=None, **params):
    params.setdefault("sheet", False)
    return run_node(bvh_character, params, work_dir=tmp_path, rotations=rot)


def read_world(path: Path, units_to_metres: float, axes: str = "x y z") -> tuple[object, np.ndarray]:
    """A BVH read back and its joint positions (n, J, 3) in world metres."""
    bvh = read_bvh(path)
    return bvh, bvh_positions(bvh) * units_to_metres @ axes_matrix(axes).T


def angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.einsum("...i,...i->...", a, b) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


# ---------------------------------------------------------------------------------------------
# a character that is the capture's own skeleton, scaled, in an A-pose, z up, centimetres, renamed
# ---------------------------------------------------------------------------------------------
def scaled_copy(rot, k: float, folder: Path) -> tuple[Path, Path]:
    """The capture's 16-joint skeleton times ``k``, arms lowered 45 degrees, names 'J_*', written z up
    in centimetres, and its mapping YAML."""
    world_from_file = axes_matrix("x z -y")
    lower = {+1: Rotation.from_euler("z", -45, degrees=True), -1: Rotation.from_euler("z", 45, degrees=True)}
    bones = []
    for j, name in enumerate(JOINT_NAMES):
        off = rot["offsets"][j] * k
        end = rot["end_offsets"][j] * k if np.any(rot["end_offsets"][j]) else None
        if name.endswith(("elbow", "wrist")):
            side = +1 if name.startswith("left") else -1
            off = lower[side].apply(off)
            end = None if end is None else lower[side].apply(end)
        to_file = world_from_file.T
        bones.append(Bone(f"J_{name}", None if j == 0 else f"J_{JOINT_NAMES[PARENTS[j]]}", tuple(to_file @ off),
                          None if end is None else tuple(to_file @ end)))
    bvh = to_bvh(bones, 100.0, "ZXY", "YXZ")
    path = write_bvh(folder / f"copy_{k}.bvh", bvh, precision=6)
    mapping = folder / "copy_mapping.yaml"
    mapping.write_text("units_to_metres: 0.01\naxes: x z -y\njoints:\n" + "".join(f"  {n}: J_{n}\n" for n in JOINT_NAMES))
    return path, mapping


@pytest.mark.parametrize("k", [0.6, 1.6])
def test_scaled_character_scales_end_effectors_exactly(rot, src, tmp_path, k):
    char, mapping = scaled_copy(rot, k, tmp_path)
    out = retarget(rot, tmp_path, character=str(char), mapping=str(mapping), floor="origin", between="rest")
    assert out["report"]["scale"] == pytest.approx(k, rel=1e-7)  # offsets printed to 1e-6 cm
    bvh, got = read_world(out["bvh"], 0.01, "x z -y")
    assert bvh.names == [f"J_{n}" for n in JOINT_NAMES]  # the character's names, order and hierarchy
    assert np.array_equal(bvh.parents, PARENTS)
    assert all(j.channels[-3:] == ("Yrotation", "Xrotation", "Zrotation") for j in bvh.joints[1:])  # its own order
    # the character's (A-pose) offsets are kept: the left forearm points 45 degrees down in its rest
    forearm = axes_matrix("x z -y") @ bvh.offsets[JOINT_INDEX["left_wrist"]]
    assert angles_deg(forearm, np.array([1.0, -1.0, 0.0])) < 1e-4
    # wrists, ankles and head relative to the root: k times the capture's, every frame
    for name in ("left_wrist", "right_wrist", "left_ankle", "right_ankle", "head"):
        j = JOINT_INDEX[name]
        err = np.abs((got[:, j] - got[:, 0]) - k * (src[:, j] - src[:, 0])).max()
        assert err < 1e-6, f"{name}: {err * 1000:.4f} mm"
    assert np.abs(got[:, 0] - k * src[:, 0]).max() < 1e-6  # the root path is scaled too
    # and they really moved (not a trivial comparison)
    assert np.ptp(got[:, JOINT_INDEX["left_ankle"], 2]) > 0.5 * k


# ---------------------------------------------------------------------------------------------
# the bundled Mixamo-like A-pose character (other names, other proportions, extra joints)
# ---------------------------------------------------------------------------------------------
def char_rest(path: Path, units: float) -> tuple[object, np.ndarray]:
    """The character file and its rest positions (J, 3) metres, root at the origin (zero rotations)."""
    bvh = read_bvh(path)
    ident = np.tile([0.0, 0.0, 0.0, 1.0], (1, len(bvh.joints), 1))
    return bvh, forward_kinematics(bvh.parents, bvh.offsets * units, ident, np.zeros((1, 3)))[0][0]


def test_apose_bone_directions_match_the_capture(rot, src, tmp_path):
    out = retarget(rot, tmp_path, character=str(APOSE), mapping="mixamo", between="rest")
    bvh, got = read_world(out["bvh"], 0.01)
    t = {n: bvh.joint_index(MIXAMO[n]) for n in JOINT_NAMES}
    # limbs, neck->head and (with between=rest) hips->chest: the capture's world directions, every frame
    for name in LIMB_BONES + ["neck", "chest"]:
        p = JOINT_NAMES[PARENTS[JOINT_INDEX[name]]]
        err = angles_deg(got[:, t[name]] - got[:, t[p]], src[:, JOINT_INDEX[name]] - src[:, JOINT_INDEX[p]])
        assert err.max() < 1e-3, f"{name}: {err.max():.5f} deg"
    # bones leaving the pelvis / chest: the capture's direction up to the constant difference between
    # the two rest shapes once the spine is aligned exactly and the left-right axis as well as possible
    _, rest_t = char_rest(APOSE, 0.01)
    rest_s = forward_kinematics(PARENTS, rot["offsets"], np.tile([0.0, 0.0, 0.0, 1.0], (1, 16, 1)), np.zeros((1, 3)))[0][0]
    for torso, spine, left, right in (("hips", "chest", "left_hip", "right_hip"),
                                      ("chest", "neck", "left_shoulder", "right_shoulder")):
        i = JOINT_INDEX
        align, _ = Rotation.align_vectors(
            [rest_s[i[spine]] - rest_s[i[torso]], rest_s[i[left]] - rest_s[i[right]]],
            [rest_t[t[spine]] - rest_t[t[torso]], rest_t[t[left]] - rest_t[t[right]]], weights=[np.inf, 1.0])
        for name in (left, right):
            misfit = angles_deg(align.apply(rest_t[t[name]] - rest_t[t[torso]]), rest_s[i[name]] - rest_s[i[torso]])
            err = angles_deg(got[:, t[name]] - got[:, t[torso]], src[:, i[name]] - src[:, i[torso]])
            assert np.abs(err - misfit).max() < 1e-3, f"{name}: {err.max():.3f} vs rest misfit {misfit:.3f} deg"
    # the report agrees with these measurements
    rep = out["report"]["bone_direction_error_deg"]
    assert max(rep[n]["max"] for n in LIMB_BONES) < 1e-3 and out["report"]["self_check_worst_mm"] < 0.1


def test_apose_rest_pose_is_respected(rot, tmp_path):
    """A capture posed into the character's rest directions gives all-zero rotations (the A-pose);
    the capture's own T-pose lifts the character's arms to horizontal."""
    char_bvh, rest_t = char_rest(APOSE, 0.01)
    t = [char_bvh.joint_index(MIXAMO[n]) for n in JOINT_NAMES]
    rest_s = forward_kinematics(PARENTS, rot["offsets"], np.tile([0.0, 0.0, 0.0, 1.0], (1, 16, 1)), np.zeros((1, 3)))[0][0]
    world = [Rotation.identity()] * 16
    kids = {j: [c for c in range(16) if PARENTS[c] == j] for j in range(16)}
    for j in range(16):  # world rotation taking the capture's rest bones onto the character's
        i = JOINT_INDEX
        if JOINT_NAMES[j] in ("hips", "chest"):
            spine, left, right = (("chest", "left_hip", "right_hip") if j == 0 else ("neck", "left_shoulder", "right_shoulder"))
            world[j] = Rotation.align_vectors(
                [rest_t[t[i[spine]]] - rest_t[t[j]], rest_t[t[i[left]]] - rest_t[t[i[right]]]],
                [rest_s[i[spine]] - rest_s[j], rest_s[i[left]] - rest_s[i[right]]], weights=[np.inf, 1.0])[0]
        elif kids[j]:
            c = kids[j][0]
            world[j] = Rotation.align_vectors([rest_t[t[c]] - rest_t[t[j]]], [rest_s[c] - rest_s[j]])[0]
        else:
            world[j] = world[PARENTS[j]]
    local = np.array([(world[j] if j == 0 else world[PARENTS[j]].inv() * world[j]).as_quat() for j in range(16)])
    posed = {**rot, "local_quat": np.stack([local, np.tile([0.0, 0.0, 0.0, 1.0], (16, 1))]),
             "root_position": np.array([[0.0, 0.9, 0.0], [0.0, 0.9, 0.0]]), "fps": np.asarray(30.0)}
    out = retarget(posed, tmp_path, character=str(APOSE), mapping="mixamo", between="distribute")
    bvh = read_bvh(out["bvh"])
    assert np.allclose(bvh.offsets[1:], char_bvh.offsets[1:], atol=1e-6)  # the character's own rest offsets
    assert bvh.names == char_bvh.names
    rotation_cols = [bvh.channel_index(j, c) for j in range(len(bvh.joints)) for c in bvh.joints[j].channels
                     if c.endswith("rotation")]
    assert np.abs(bvh.motion[0, rotation_cols]).max() < 1e-4  # frame 0: every joint at rest (degrees)
    # frame 1, the capture's T-pose: the character's upper arms and forearms are horizontal
    pos = bvh_positions(bvh)[1] * 0.01
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        for a, b in ((f"{side}Arm", f"{side}ForeArm"), (f"{side}ForeArm", f"{side}Hand")):
            d = pos[bvh.joint_index(f"mixamorig:{b}")] - pos[bvh.joint_index(f"mixamorig:{a}")]
            assert angles_deg(d, np.array([sign, 0.0, 0.0])) < 1e-3


def test_spine_bend_is_split_and_extra_joints_stay_at_rest(rot, tmp_path):
    out = retarget(rot, tmp_path, character=str(APOSE), mapping="mixamo", between="distribute")
    bvh = read_bvh(out["bvh"])
    local, _ = bvh_to_local(bvh)
    q = {n: local[:, bvh.joint_index(f"mixamorig:{n}")] for n in
         ("Spine", "Spine1", "Spine2", "LeftShoulder", "LeftHandIndex1", "RightHandThumb2", "LeftToeBase")}
    angle = lambda x: np.degrees(Rotation.from_quat(x).magnitude())  # noqa: E731
    # the bend between Hips and Spine2 is split evenly over Spine, Spine1, Spine2
    for a, b in (("Spine", "Spine1"), ("Spine1", "Spine2")):
        diff = Rotation.from_quat(q[a]).inv() * Rotation.from_quat(q[b])
        assert np.degrees(diff.magnitude()).max() < 1e-3
    assert angle(q["Spine"]).max() > 1.0
    # clavicle, fingers and toes: at rest relative to their parent
    for n in ("LeftShoulder", "LeftHandIndex1", "RightHandThumb2", "LeftToeBase"):
        assert angle(q[n]).max() < 1e-4, n
    assert out["report"]["distributed"] == {"chest": ["mixamorig:Spine", "mixamorig:Spine1"]}
    assert "mixamorig:LeftShoulder" in out["report"]["at_rest"]
    # with between=rest the intermediate spine joints do not move
    out = retarget(rot, tmp_path, character=str(APOSE), mapping="mixamo", between="rest")
    local, _ = bvh_to_local(read_bvh(out["bvh"]))
    assert angle(local[:, bvh.joint_index("mixamorig:Spine")]).max() < 1e-4


@pytest.mark.parametrize("character, mapping, units, ankles", [
    (CHILD, "cmu", 0.05644, ("LeftAnkle", "RightAnkle")),
    (APOSE, "mixamo", 0.01, ("mixamorig:LeftFoot", "mixamorig:RightFoot")),
])
def test_feet_reach_the_floor_whatever_the_size(rot, src, tmp_path, character, mapping, units, ankles):
    out = retarget(rot, tmp_path, character=str(character), mapping=mapping)
    char_bvh, rest = char_rest(character, units)
    ia = [char_bvh.joint_index(n) for n in ankles]
    hips = char_bvh.joint_index("Hips" if mapping == "cmu" else "mixamorig:Hips")
    leg = rest[hips, 1] - rest[ia, 1].mean()
    leg_src = -(rot["offsets"][[10, 11, 12]].sum(axis=0)[1] + rot["offsets"][[13, 14, 15]].sum(axis=0)[1]) / 2
    assert out["report"]["scale"] == pytest.approx(leg / leg_src, rel=1e-9)
    bvh, got = read_world(out["bvh"], units)
    ends = [(rest + np.array([j.end_site if j.end_site is not None else np.zeros(3) for j in char_bvh.joints]) * units)]
    lowest_rest = min(rest[:, 1].min(), ends[0][:, 1].min())
    planted = rest[ia, 1].mean() - lowest_rest  # the character's ankle height when standing on y = 0
    low = np.percentile(got[:, ia, 1], 5)
    assert abs(low - planted) < 0.005, f"planted ankles at {low:.4f} m, standing height {planted:.4f} m"
    # strides scale with the legs
    travel = np.ptp(got[:, hips, 2])
    assert travel == pytest.approx(out["report"]["scale"] * np.ptp(src[:, 0, 2]), rel=1e-6)


# ---------------------------------------------------------------------------------------------
# mistakes
# ---------------------------------------------------------------------------------------------
def test_mapping_mistakes_are_named(rot, tmp_path):
    bad = tmp_path / "bad.yaml"
    text = (REPO / "tbha_graph" / "mocap" / "io" / "mappings" / "mixamo.yaml").read_text()
    bad.write_text(text.replace("mixamorig:LeftForeArm", "mixamorig:LeftForArm"))
    with pytest.raises(NodeError, match=r"bad.yaml:\d+.*LeftForArm.*did you mean 'mixamorig:LeftForeArm'"):
        retarget(rot, tmp_path, character=str(APOSE), mapping=str(bad))
    bad.write_text(text.replace("left_elbow: mixamorig:LeftForeArm", "left_elbow: mixamorig:RightForeArm")
                   .replace("right_elbow: mixamorig:RightForeArm", "right_elbow: mixamorig:LeftForeArm"))
    with pytest.raises(NodeError, match="'left_elbow: mixamorig:RightForeArm' is not below 'left_shoulder"):
        retarget(rot, tmp_path, character=str(APOSE), mapping=str(bad))
    with pytest.raises(NodeError, match="preset 'mixamo' needs a Mixamo-named character"):
        retarget(rot, tmp_path, character=str(CHILD), mapping="cmu", preset="mixamo")
    with pytest.raises(NodeError, match="no skeleton mapping 'mixamoo'.*did you mean 'mixamo'"):
        retarget(rot, tmp_path, character=str(APOSE), mapping="mixamoo")
