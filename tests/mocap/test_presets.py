"""Export presets (blender, y-up, mixamo) on export.bvh and retarget.bvh_character: file layout, the
read-back self-check passing on real motion and failing on a wrong axis, the contact sheet."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.export import presets
from tbha_graph.mocap.export.bvh import export_bvh
from tbha_graph.mocap.io.bvh import bvh_positions, read_bvh
from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.retarget.bvh_character import bvh_character
from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "data" / "mocap" / "cmu" / "131_02.bvh"
CHILD = REPO / "data" / "characters" / "child.bvh"
#: Blender's default BVH import maps file (x, y, z) to Blender (x, -z, y) (measured with bpy 5.0.1,
#: tests/integration/test_blender_import.py)
BLENDER_DEFAULT_IMPORT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def rot() -> dict[str, np.ndarray]:
    r = rotations16_from_bvh(CLIP)
    return {**r, "local_quat": r["local_quat"][::10].copy(), "root_position": r["root_position"][::10].copy(),
            "fps": np.asarray(12.0)}


@pytest.fixture(scope="module")
def fk(rot) -> np.ndarray:
    return forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])[0]


EXPECTED = {  # preset: (file units per metre, rotation channels, root joint name)
    "blender": (1.0, ("Xrotation", "Yrotation", "Zrotation"), "hips"),
    "y-up": (100.0, ("Zrotation", "Xrotation", "Yrotation"), "hips"),
    "mixamo": (100.0, ("Zrotation", "Xrotation", "Yrotation"), "mixamorig:Hips"),
}


@pytest.mark.parametrize("preset", list(EXPECTED))
def test_each_preset_writes_its_layout_and_passes_on_real_motion(rot, fk, preset, tmp_path):
    out = run_node(export_bvh, {"preset": preset, "sheet": False}, work_dir=tmp_path, rotations=rot)
    units, channels, root = EXPECTED[preset]
    bvh = read_bvh(out["bvh"])
    assert bvh.joints[0].name == root and bvh.joints[1].channels == channels
    got = bvh_positions(bvh) / units
    assert np.abs(got - fk).max() < 1e-4  # y up, faces +z in the file for every preset: same numbers
    if preset == "mixamo":
        assert bvh.names[JOINT_INDEX["left_shoulder"]] == "mixamorig:LeftArm"
        assert bvh.names[JOINT_INDEX["left_knee"]] == "mixamorig:LeftLeg"
        assert bvh.offsets[JOINT_INDEX["left_elbow"]][0] > 20.0  # T-pose rest, centimetres
    if preset == "blender":  # after Blender's default import: z up, the actor faces -Y
        b = bvh.offsets @ BLENDER_DEFAULT_IMPORT.T
        rest = forward_kinematics(PARENTS, b, np.tile([0.0, 0.0, 0.0, 1.0], (1, 16, 1)), np.zeros((1, 3)))[0][0]
        up = rest[JOINT_INDEX["head"]] - rest[JOINT_INDEX["hips"]]
        facing = np.cross(rest[JOINT_INDEX["left_hip"]] - rest[JOINT_INDEX["right_hip"]], [0.0, 0.0, 1.0])
        assert up[2] > 0.95 * np.linalg.norm(up)
        assert facing[1] < -0.9 * np.linalg.norm(facing)


def test_self_check_fails_on_a_wrong_axis_conversion(rot, monkeypatch, tmp_path):
    """The writer's axis conversion flipped (a 90-degree turn about x): the read-back check catches it."""
    honest = presets.to_file_axes

    def flipped(preset, offsets, ends, local, root):
        return honest(preset.replace(file_axes="x z -y"), offsets, ends, local, root)

    monkeypatch.setattr(presets, "to_file_axes", flipped)
    for preset in EXPECTED:
        with pytest.raises(NodeError, match=r"self-check failed: reading motion.bvh back puts joint '.*' [\d.]+ mm"):
            run_node(export_bvh, {"preset": preset, "sheet": False}, work_dir=tmp_path, rotations=rot)


def test_self_check_fails_when_a_preset_would_import_lying_down(rot, monkeypatch, tmp_path):
    """A 'blender' preset writing a z-up file is self-consistent but Blender's default import would lay
    the actor on its back: the orientation check refuses it."""
    monkeypatch.setitem(presets.PRESETS, "blender", presets.PRESETS["blender"].replace(file_axes="x -z y"))
    with pytest.raises(NodeError, match=r"would lean (8\d|9\d) degrees off 'z' up"):
        run_node(export_bvh, {"preset": "blender", "sheet": False}, work_dir=tmp_path, rotations=rot)


def test_explicit_params_override_the_preset(rot, fk, tmp_path):
    out = run_node(export_bvh, {"preset": "y-up", "scale": 1.0, "rotation_order": "YZX", "sheet": False},
                   work_dir=tmp_path, rotations=rot)
    bvh = read_bvh(out["bvh"])
    assert bvh.joints[2].channels == ("Yrotation", "Zrotation", "Xrotation")
    assert np.abs(bvh_positions(bvh) - fk).max() < 1e-4


@pytest.mark.parametrize("preset, units", [("blender", 1.0), ("y-up", 100.0), ("character", 1 / 0.05644)])
def test_retarget_presets_pass_on_real_motion(rot, preset, units, tmp_path):
    out = run_node(bvh_character, {"character": str(CHILD), "mapping": "cmu", "preset": preset, "sheet": False},
                   work_dir=tmp_path, rotations=rot)
    bvh = read_bvh(out["bvh"])
    hips = bvh.joint_index("Hips")
    pos = bvh_positions(bvh) / units
    assert 0.5 < np.median(pos[:, hips, 1]) < 0.75  # a child's pelvis height in metres
    assert out["report"]["self_check_worst_mm"] < 0.1 and out["report"]["preset"] == preset


def test_retarget_self_check_fails_on_a_wrong_axis_conversion(rot, monkeypatch, tmp_path):
    honest = presets.to_file_axes
    monkeypatch.setattr(presets, "to_file_axes",
                        lambda p, *a: honest(p.replace(file_axes="-x y -z"), *a))  # turned round
    with pytest.raises(NodeError, match="self-check failed"):
        run_node(bvh_character, {"character": str(CHILD), "mapping": "cmu", "preset": "y-up", "sheet": False},
                 work_dir=tmp_path, rotations=rot)


def test_contact_sheet_is_drawn_in_the_application_axes(rot, tmp_path):
    out = run_node(export_bvh, {"preset": "blender", "sheet_frames": 3}, work_dir=tmp_path, rotations=rot)
    img = cv2.imread(str(out["sheet"]))
    assert img is not None and img.shape[1] > 400 and img.shape[0] > 300
    assert (img < 128).any(axis=2).mean() > 0.01  # something is drawn
    blue = (img[..., 0] > 150) & (img[..., 2] < 100)  # the left side (tab:blue), BGR
    red = (img[..., 2] > 150) & (img[..., 0] < 100)
    assert blue.sum() > 50 and red.sum() > 50
    off = run_node(export_bvh, {"preset": "blender", "sheet": False}, work_dir=tmp_path / "off", rotations=rot)
    small = cv2.imread(str(off["sheet"]))
    assert small is not None and small.shape[0] < 100  # the placeholder


def test_unknown_preset_is_refused(rot):
    with pytest.raises(ValidationError, match="preset"):
        run_node(export_bvh, {"preset": "maya"}, rotations=rot)
    assert set(presets.PRESET_NAMES) == {"blender", "y-up", "mixamo"}
    assert JOINT_NAMES[0] == "hips"


def test_build_bvh_at_gimbal_lock_warns_nothing(no_hidden_warnings):
    """Joints in two Euler orders, each at gimbal lock (middle angle 90 degrees) in one frame: channel angles
    that give the rotations back (third angle 0), no warning emitted and none hidden."""
    from scipy.spatial.transform import Rotation

    angles = np.array([[10.0, 90.0, 20.0], [10.0, 40.0, 20.0]])
    q = np.stack([Rotation.from_euler(o, angles, degrees=True).as_quat() for o in ("ZXY", "XYZ")], axis=1)
    with no_hidden_warnings():
        bvh = presets.build_bvh(["hips", "chest"], np.array([-1, 0]), np.array([[0.0, 0, 0], [0, 0.5, 0]]),
                                [None, np.array([0.0, 0.5, 0])], q, np.zeros((2, 3)), 0.1, ["ZXY", "XYZ"])
    back = np.array([[30.0, 90.0, 0.0], [10.0, 40.0, 20.0]])
    np.testing.assert_allclose(bvh.motion[:, 3:6], back, atol=1e-9)
    np.testing.assert_allclose(bvh.motion[:, 6:9], back, atol=1e-9)
    assert bvh.joints[1].channels == ("Xrotation", "Yrotation", "Zrotation")
