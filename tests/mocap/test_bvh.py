"""BVH reading/writing: real CMU clips, hand-made unusual files, an independent oracle, malformed files."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.spatial.transform import Rotation

from tbha_graph.core.errors import NodeError
from tbha_graph.mocap.io.bvh import (
    Bvh,
    BvhError,
    bvh_from_local,
    bvh_positions,
    bvh_to_local,
    end_site_positions,
    quat_to_euler,
    read_bvh,
    write_bvh,
)

CMU_DIR = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu"
CMU_CLIPS = ["131_01.bvh", "131_02.bvh", "131_03.bvh"]
CMU_UNIT_MM = 56.44  # 1 CMU unit = 0.05644 m


# ---------------------------------------------------------------------------------------------
# real files
# ---------------------------------------------------------------------------------------------
def test_cmu_clip_structure() -> None:
    bvh = read_bvh(CMU_DIR / "131_01.bvh")
    assert bvh.n_frames == 720 and len(bvh.joints) == 31 and bvh.n_channels == 96
    assert bvh.frame_time == pytest.approx(0.0083333) and bvh.fps == pytest.approx(120.0, rel=1e-4)
    assert bvh.names[0] == "Hips" and bvh.parents[0] == -1
    assert bvh.joints[0].channels == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    # mixed orders within one file are kept per joint
    assert bvh.joints[bvh.joint_index("LeftElbow")].channels == ("Zrotation", "Xrotation", "Yrotation")
    assert bvh.joints[bvh.joint_index("LeftKnee")].channels == ("Zrotation", "Yrotation", "Xrotation")
    # first value of the first motion line, and the LeftToe End Site, as written in the file
    assert bvh.motion[0, bvh.channel_index("Hips", "Xposition")] == pytest.approx(5.2300)
    assert np.allclose(bvh.joints[bvh.joint_index("LeftToe")].end_site, [0.0, 0.0, 1.13491])
    # LeftHip rest offset: the hip joint sits at +x (actor's left), below the pelvis
    assert np.allclose(bvh.offsets[bvh.joint_index("LeftHip")], [1.24777, -1.64261, 0.71711])


@pytest.mark.parametrize("clip", CMU_CLIPS)
def test_cmu_round_trip(clip: str, tmp_path: Path) -> None:
    src = read_bvh(CMU_DIR / clip)
    out = write_bvh(tmp_path / clip, src)
    back = read_bvh(out)
    assert back.names == src.names and np.array_equal(back.parents, src.parents)
    assert [j.channels for j in back.joints] == [j.channels for j in src.joints]
    assert back.frame_time == src.frame_time
    assert np.allclose(back.offsets, src.offsets, atol=5e-7, rtol=0)
    assert np.allclose(back.motion, src.motion, atol=5e-7, rtol=0)
    err_mm = np.abs(bvh_positions(back) - bvh_positions(src)).max() * CMU_UNIT_MM
    assert err_mm < 0.01
    assert b"\r" not in out.read_bytes()


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX"])
def test_euler_decomposition_round_trip(order: str, tmp_path: Path) -> None:
    """bvh_to_local -> bvh_from_local in another Euler order -> file -> same joint positions."""
    src = read_bvh(CMU_DIR / "131_03.bvh")
    src = Bvh(src.joints, src.frame_time, src.motion[::6])
    local, root = bvh_to_local(src)
    rebuilt = bvh_from_local(src.names, src.parents, src.offsets, [j.end_site for j in src.joints],
                             local, root, src.frame_time, order=order)
    assert rebuilt.joints[0].channels[3:] == tuple(f"{a}rotation" for a in order)
    back = read_bvh(write_bvh(tmp_path / "r.bvh", rebuilt))
    err_mm = np.abs(bvh_positions(back) - bvh_positions(src)).max() * CMU_UNIT_MM
    assert err_mm < 0.01
    # unwrapped: no 360-degree jump between consecutive frames
    assert np.abs(np.diff(back.motion[:, 3:], axis=0)).max() < 180


#: Middle angle +90, -90 and not locked: the angles given and those expected back (at gimbal lock the third
#: angle is 0 and the first carries the rest; ZXY and XYZ alike)
LOCKED = np.array([[10.0, 90.0, 20.0], [10.0, -90.0, 20.0], [10.0, 40.0, 20.0]])
LOCKED_BACK = np.array([[30.0, 90.0, 0.0], [-10.0, -90.0, 0.0], [10.0, 40.0, 20.0]])


@pytest.mark.parametrize("order", ["ZXY", "XYZ"])
def test_gimbal_lock_gives_the_rotation_and_warns_nothing(order: str, no_hidden_warnings) -> None:
    """quat_to_euler and bvh_from_local at gimbal lock: angles that give the rotation back, no warning
    emitted and none hidden."""
    q = Rotation.from_euler(order, LOCKED, degrees=True).as_quat()
    local = np.stack([np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)), q], axis=1)  # (3 frames, 2 joints, 4)
    with no_hidden_warnings():
        eul = quat_to_euler(local, order)
        built = bvh_from_local(["root", "arm"], np.array([-1, 0]), np.array([[0.0, 0, 0], [0, 1, 0]]), None,
                               local, np.zeros((3, 3)), 0.1, order=order)
    assert eul.shape == (3, 2, 3)
    np.testing.assert_allclose(eul[:, 1], LOCKED_BACK, atol=1e-9)
    np.testing.assert_allclose(built.motion[:, 6:], LOCKED_BACK, atol=1e-9)
    back, _ = bvh_to_local(built)
    np.testing.assert_allclose(np.abs(np.sum(back[:, 1] * q, axis=-1)), 1.0, atol=1e-12)  # the same rotations


def test_agrees_with_bvhio_on_cmu(tmp_path: Path) -> None:
    """Independent oracle: bvhio's own parser and FK on the first 40 frames of a CMU clip."""
    bvhio = pytest.importorskip("bvhio", reason="bvhio (test extra) is not installed")
    src = read_bvh(CMU_DIR / "131_02.bvh")
    path = CMU_DIR / "131_02.bvh"
    short = tmp_path / "short.bvh"
    # keep the original header bytes, only fewer motion lines
    lines = path.read_bytes().splitlines(keepends=True)
    k = next(i for i, s in enumerate(lines) if s.startswith(b"Frames:"))
    short.write_bytes(b"".join(lines[:k]) + b"Frames: 40\n" + b"".join(lines[k + 1: k + 2 + 40]))
    ours = bvh_positions(read_bvh(short))
    assert np.allclose(ours, bvh_positions(src)[:40])
    root = bvhio.readAsHierarchy(str(short))
    layout = root.layout()
    assert [j.Name for j, _, _ in layout] == src.names
    ref = np.zeros_like(ours)
    for f in range(40):
        root.loadPose(f)
        ref[f] = [list(j.PositionWorld) for j, _, _ in layout]
    assert np.abs(ours - ref).max() * CMU_UNIT_MM < 0.01


# ---------------------------------------------------------------------------------------------
# hand-made files with unusual layouts
# ---------------------------------------------------------------------------------------------
UNUSUAL = (
    "HIERARCHY\r\n"
    "ROOT pelvis  \r\n"
    "{\n"
    "  OFFSET 0 0 0\r\n"
    "\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\n"
    "\tJOINT slider\r\n"
    "    {\n"
    "\t\tOFFSET\t0.0\t1.5\t0.0\n"
    "CHANNELS 6 Zposition Xposition Yposition Xrotation Zrotation Yrotation\r\n"
    "\t\tJOINT tip\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0 0 0\n"
    "\t\t\tCHANNELS 3 Yrotation Xrotation Zrotation   \n"
    "\t\t\tEnd Site\n"
    "\t\t\t{\n"
    "\t\t\t\tOFFSET 0.0 0.0 2.0\n"
    "\t\t\t}\n"
    "\t\t}\n"
    "\t}\n"
    "\tJOINT side\n"
    "\t{\n"
    "\t\tOFFSET 1 0 0\n"
    "\t\tCHANNELS 3 Xrotation Yrotation Zrotation\n"
    "\t\tEnd Site\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0.5 0 0\n"
    "\t\t}\n"
    "\t}\n"
    "}\r\n"
    "MOTION\r\n"
    "Frames:\t2\n"
    "Frame Time: 0.033333333333\r\n"
    "1 2 3 10 20 30 0.5 0.25 2 40 -50 60 70 80 -90 15 25 35  \r\n"
    "-1 0 0 0 0 0 0 0 0 0 0 0 0 0 90 0 0 90\n"
    "\n"
)


def test_unusual_layout_is_read_with_each_joints_own_order(tmp_path: Path) -> None:
    path = tmp_path / "unusual.bvh"
    path.write_bytes(UNUSUAL.encode())
    bvh = read_bvh(path)
    assert bvh.names == ["pelvis", "slider", "tip", "side"]
    assert list(bvh.parents) == [-1, 0, 1, 0]
    assert bvh.frame_time == 0.033333333333 and bvh.n_frames == 2
    pos = bvh_positions(bvh)

    # expected, computed independently with scipy matrices (intrinsic = upper-case order)
    def rot(order: str, angles: list[float]) -> np.ndarray:
        return Rotation.from_euler(order, angles, degrees=True).as_matrix()

    r_root = rot("YXZ", [10, 20, 30])
    p_root = np.array([1.0, 2.0, 3.0])
    # slider: position channels Z X Y = 0.5 0.25 2 replace its offset
    p_slider = p_root + r_root @ np.array([0.25, 2.0, 0.5])
    r_slider = r_root @ rot("XZY", [40, -50, 60])
    p_tip = p_slider + r_slider @ np.zeros(3)
    p_side = p_root + r_root @ np.array([1.0, 0.0, 0.0])
    assert np.allclose(pos[0], [p_root, p_slider, p_tip, p_side], atol=1e-12)
    # tip's own YXZ order matters: its End Site lands where YXZ puts it
    end_tip = end_site_positions(bvh)[2][0]
    assert np.allclose(end_tip, p_tip + r_slider @ rot("YXZ", [70, 80, -90]) @ [0, 0, 2.0], atol=1e-12)

    # round trip through our writer keeps channels, values and positions
    back = read_bvh(write_bvh(tmp_path / "out.bvh", bvh, precision=8))
    assert [j.channels for j in back.joints] == [j.channels for j in bvh.joints]
    assert np.allclose(back.motion, bvh.motion) and np.allclose(bvh_positions(back), pos, atol=1e-9)
    assert back.joints[2].end_site is not None and back.joints[1].end_site is None


def test_unusual_layout_agrees_with_bvhio(tmp_path: Path) -> None:
    bvhio = pytest.importorskip("bvhio", reason="bvhio (test extra) is not installed")
    path = tmp_path / "unusual.bvh"
    path.write_bytes(UNUSUAL.encode())
    ours = bvh_positions(read_bvh(path))
    root = bvhio.readAsHierarchy(str(path))
    layout = root.layout()
    for f in range(2):
        root.loadPose(f)
        ref = np.array([list(j.PositionWorld) for j, _, _ in layout])
        assert np.abs(ours[f] - ref).max() < 1e-5


# ---------------------------------------------------------------------------------------------
# malformed files
# ---------------------------------------------------------------------------------------------
GOOD = """HIERARCHY
ROOT hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT knee
\t{
\t\tOFFSET 0 -1 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -1 0
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.0083333
0 1 0 0 0 0 0 0 0
0 1 0 0 0 0 10 0 0
0 1 0 0 0 0 20 0 0
"""


def _mutate(old: str, new: str) -> str:
    assert old in GOOD
    return GOOD.replace(old, new, 1)


MALFORMED = {
    # name: (file text, expected line number, a word the message must contain)
    "truncated_motion": (GOOD.rsplit("0 1 0 0 0 0 20 0 0\n", 1)[0], 20, "truncated"),
    "short_line": (_mutate("0 1 0 0 0 0 10 0 0", "0 1 0 0 0 0 10 0"), 20, "8 values"),
    "long_line": (_mutate("0 1 0 0 0 0 20 0 0", "0 1 0 0 0 0 20 0 0 7"), 21, "10 values"),
    "bad_number_motion": (_mutate("0 1 0 0 0 0 10 0 0", "0 1 0 0 0 0 1O 0 0"), 20, "'1O'"),
    "nan_motion": (_mutate("0 1 0 0 0 0 20 0 0", "0 1 0 nan 0 0 20 0 0"), 21, "'nan'"),
    "bad_number_offset": (_mutate("OFFSET 0 -1 0\n\t\tCHANNELS", "OFFSET 0 -l 0\n\t\tCHANNELS"), 8, "'-l'"),
    "unknown_channel": (_mutate("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Xrot Yrotation"), 9, "Xrot"),
    "channel_count_too_big": (_mutate("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), 10, "unknown channel 'End'"),
    "missing_close_brace": (_mutate("\t}\n}\nMOTION", "\t}\nMOTION"), 15, "'}'"),
    "missing_open_brace": (_mutate("\tJOINT knee\n\t{", "\tJOINT knee"), 7, "'{'"),
    "bad_frames": (_mutate("Frames: 3", "Frames: three"), 17, "Frames"),
    "bad_frame_time": (_mutate("Frame Time: 0.0083333", "Frame Time: 0"), 18, "Frame Time"),
    "extra_lines": (_mutate("Frames: 3", "Frames: 2"), 17, "extra"),
    "no_motion": (GOOD.split("MOTION")[0], 15, "MOTION"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_name_file_and_line(case: str, tmp_path: Path) -> None:
    text, line, word = MALFORMED[case]
    path = tmp_path / f"broken_{case}.bvh"
    path.write_text(text)
    with pytest.raises(BvhError) as info:
        read_bvh(path)
    msg = str(info.value)
    assert isinstance(info.value, NodeError)
    assert f"broken_{case}.bvh:{line}" in msg, msg
    assert word in msg, msg


def test_good_reference_file_reads(tmp_path: Path) -> None:
    """The base of the malformed cases is itself valid (so each case fails for its own reason)."""
    path = tmp_path / "good.bvh"
    path.write_text(GOOD)
    bvh = read_bvh(path)
    pos = bvh_positions(bvh)
    # knee 1 below the hips, hips at y=1; frame 2 turns the knee 10 deg about z, swinging its End Site
    assert np.allclose(pos[:, :], [[0, 1, 0], [0, 0, 0]])
    s, c = np.sin(np.radians(10)), np.cos(np.radians(10))
    assert np.allclose(end_site_positions(bvh)[1][1], [s, -c, 0])


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(BvhError, match="nope.bvh"):
        read_bvh(tmp_path / "nope.bvh")


def test_writer_is_atomic_and_refuses_bad_motion(tmp_path: Path) -> None:
    path = tmp_path / "good.bvh"
    path.write_text(GOOD)
    bvh = read_bvh(path)
    before = path.read_bytes()
    bad = Bvh(bvh.joints, bvh.frame_time, np.full((2, 9), np.nan))
    with pytest.raises(ValueError, match="NaN"):
        write_bvh(path, bad)
    assert path.read_bytes() == before  # nothing partial written
    assert [p.name for p in tmp_path.iterdir()] == ["good.bvh"]


# ---------------------------------------------------------------------------------------------
# export.bvh node on real CMU-derived motion
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cmu_rotations() -> dict[str, np.ndarray]:
    from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh

    rot = rotations16_from_bvh(CMU_DIR / "131_01.bvh")
    rot["local_quat"] = rot["local_quat"][::3].copy()
    rot["root_position"] = rot["root_position"][::3].copy()
    rot["fps"] = np.asarray(40.0)
    return rot


def _fk_in(rot: dict[str, np.ndarray]) -> np.ndarray:
    from tbha_graph.mocap.kinematics import forward_kinematics
    from tbha_graph.mocap.skeleton import PARENTS

    return forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])[0]


def test_export_bvh_writes_the_16_joint_skeleton(cmu_rotations: dict[str, np.ndarray]) -> None:
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.export.bvh import export_bvh
    from tbha_graph.mocap.skeleton import JOINT_NAMES, PARENTS

    path = run_node(export_bvh, {}, rotations=cmu_rotations)["bvh"]
    assert path.name == "motion.bvh"
    bvh = read_bvh(path)
    assert bvh.names == list(JOINT_NAMES) and np.array_equal(bvh.parents, PARENTS)
    assert bvh.joints[0].channels == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert all(j.channels == ("Zrotation", "Xrotation", "Yrotation") for j in bvh.joints[1:])
    leaves = {j.name for j in bvh.joints if j.end_site is not None}
    assert leaves == {"head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"}
    assert bvh.n_frames == 240 and bvh.fps == pytest.approx(40.0)
    # metres, and every joint where the input's forward kinematics puts it (0.1 mm)
    assert np.abs(bvh_positions(bvh) - _fk_in(cmu_rotations)).max() < 1e-4
    # rest pose is the T-pose: left arm along +x, legs down
    assert bvh.offsets[JOINT_NAMES.index("left_elbow")][0] > 0.2
    assert bvh.offsets[JOINT_NAMES.index("right_elbow")][0] < -0.2
    assert bvh.offsets[JOINT_NAMES.index("left_knee")][1] < -0.35


def test_export_bvh_scale_and_order(cmu_rotations: dict[str, np.ndarray]) -> None:
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.export.bvh import export_bvh

    path = run_node(export_bvh, {"scale": 100, "rotation_order": "YXZ"}, rotations=cmu_rotations)["bvh"]
    bvh = read_bvh(path)
    assert bvh.joints[3].channels == ("Yrotation", "Xrotation", "Zrotation")
    assert np.abs(bvh_positions(bvh) / 100 - _fk_in(cmu_rotations)).max() < 1e-4
    with pytest.raises(ValidationError, match="rotation_order"):
        run_node(export_bvh, {"rotation_order": "ZXX"}, rotations=cmu_rotations)


def test_export_bvh_self_check_fails_when_too_few_decimals(cmu_rotations: dict[str, np.ndarray]) -> None:
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.export.bvh import export_bvh

    with pytest.raises(NodeError, match="self-check failed.*mm"):
        run_node(export_bvh, {"precision": 2}, rotations=cmu_rotations)


def test_export_bvh_refuses_a_broken_rotation(cmu_rotations: dict[str, np.ndarray]) -> None:
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.export.bvh import export_bvh

    bad = dict(cmu_rotations, local_quat=cmu_rotations["local_quat"].copy())
    bad["local_quat"][3, 5] = np.nan
    with pytest.raises(NodeError, match="'left_elbow' on frame 3"):
        run_node(export_bvh, {}, rotations=bad)
