"""Skeleton mapping (CMU -> 16 TBHA joints), the io.bvh_load node and mapping errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.io.bvh import read_bvh
from tbha_graph.mocap.io.bvh_load import bvh_load
from tbha_graph.mocap.io.skeleton_map import (
    MAPPINGS_DIR,
    MappingError,
    load_mapping,
    map_positions,
    motion16_from_bvh,
)
from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES, measure_bone_lengths

CMU = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu"


@pytest.fixture(scope="module")
def walk() -> dict[str, np.ndarray]:
    return motion16_from_bvh(CMU / "131_02.bvh")


def test_cmu_mapping_is_bundled_and_complete() -> None:
    m = load_mapping("cmu")
    assert set(m.joints) == set(JOINT_NAMES)
    assert m.units_to_metres == pytest.approx(0.05644)
    assert m.joints["chest"] == "Chest2" and m.joints["left_shoulder"] == "LeftShoulder"
    assert np.array_equal(m.world_from_source(), np.eye(3))


def test_cmu_motion_in_metres_y_up(walk: dict[str, np.ndarray]) -> None:
    j = walk["joints"]
    assert j.shape == (720, 16, 3) and float(walk["fps"]) == pytest.approx(120.0, rel=1e-4)
    assert list(walk["joint_names"]) == list(JOINT_NAMES)
    y = j[..., 1]
    # a standing/walking adult: pelvis about 0.95 m up, feet near the floor, posture order on every frame
    assert 0.85 < np.median(y[:, JOINT_INDEX["hips"]]) < 1.05
    assert np.abs(np.min(y[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]])) < 0.15
    for upper, lower in [("head", "neck"), ("neck", "chest"), ("chest", "hips"), ("hips", "left_knee")]:
        assert (y[:, JOINT_INDEX[upper]] > y[:, JOINT_INDEX[lower]]).all(), (upper, lower)


def test_cmu_bone_lengths_are_rigid_and_match_the_file(walk: dict[str, np.ndarray]) -> None:
    lengths = measure_bone_lengths(walk["joints"])
    # FK of a rigid skeleton: every mapped bone is one CMU bone chain of fixed length, except
    # hips -> chest, which spans the bending spine (lowerback, Chest) and varies slightly
    spine = JOINT_INDEX["chest"]
    assert np.delete(lengths.std(axis=0), spine).max() < 1e-9
    assert 0 < lengths[:, spine].std() < 1e-3
    bvh = read_bvh(CMU / "131_02.bvh")
    knee_offset = bvh.offsets[bvh.joint_index("LeftKnee")]
    assert lengths[0, JOINT_INDEX["left_knee"]] == pytest.approx(np.linalg.norm(knee_offset) * 0.05644)
    assert 0.35 < lengths[0, JOINT_INDEX["left_knee"]] < 0.5  # a thigh, in metres


def test_left_is_the_actors_left(walk: dict[str, np.ndarray]) -> None:
    """Facing direction = (left hip - right hip) x up must agree with the direction of walking."""
    j = walk["joints"]
    left = j[:, JOINT_INDEX["left_hip"]] - j[:, JOINT_INDEX["right_hip"]]
    forward = np.cross(left, [0.0, 1.0, 0.0])
    velocity = np.gradient(j[:, JOINT_INDEX["hips"]], axis=0) * 120.0
    moving = np.linalg.norm(velocity[:, [0, 2]], axis=1) > 0.3  # walking faster than 0.3 m/s
    assert moving.sum() > 100
    cos = np.sum(forward * velocity, axis=1)[moving] / (
        np.linalg.norm(forward, axis=1) * np.linalg.norm(velocity, axis=1))[moving]
    assert np.median(cos) > 0.8


def test_units_override_and_axes(tmp_path: Path, walk: dict[str, np.ndarray]) -> None:
    cm = motion16_from_bvh(CMU / "131_02.bvh", units_to_metres=0.1)
    assert np.allclose(cm["joints"], walk["joints"] / 0.05644 * 0.1)
    text = (MAPPINGS_DIR / "cmu.yaml").read_text().replace("axes: x y z", "axes: z x y")
    path = tmp_path / "rotated.yaml"
    path.write_text(text)
    rotated = map_positions(read_bvh(CMU / "131_02.bvh"), load_mapping(path))
    assert np.allclose(rotated, walk["joints"][..., [2, 0, 1]])


def test_bvh_load_node(walk: dict[str, np.ndarray]) -> None:
    out = run_node(bvh_load, {"path": str(CMU / "131_02.bvh")})
    assert np.array_equal(out["motion"]["joints"], walk["joints"])
    with pytest.raises(ValidationError, match="greater than 0"):
        run_node(bvh_load, {"path": str(CMU / "131_02.bvh"), "units_to_metres": 0})


def _user_mapping(tmp_path: Path, old: str, new: str) -> Path:
    text = (MAPPINGS_DIR / "cmu.yaml").read_text()
    assert old in text
    path = tmp_path / "my_mapping.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_unknown_source_joint_names_mapping_file_and_suggests(tmp_path: Path) -> None:
    path = _user_mapping(tmp_path, "left_elbow: LeftElbow", "left_elbow: LeftElbw")
    line = path.read_text().splitlines().index("  left_elbow: LeftElbw") + 1
    with pytest.raises(MappingError) as info:
        motion16_from_bvh(CMU / "131_01.bvh", mapping=path)
    msg = str(info.value)
    assert f"my_mapping.yaml:{line}" in msg and "131_01.bvh" in msg
    assert "did you mean 'LeftElbow'" in msg


def test_unknown_tbha_joint_names_mapping_file(tmp_path: Path) -> None:
    path = _user_mapping(tmp_path, "left_elbow: LeftElbow", "left_elbo: LeftElbow")
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    msg = str(info.value)
    assert "my_mapping.yaml" in msg and "did you mean 'left_elbow'" in msg


@pytest.mark.parametrize(
    "old,new,word",
    [
        ("  head: Head\n", "", "['head']"),  # a joint left out
        ("axes: x y z", "axes: x y y", "axes"),
        ("axes: x y z", "axes: -x y z", "mirror"),
        ("units_to_metres: 0.05644", "units_to_metres: -1", "units_to_metres"),
        ("joints:", "joints: [", "YAML syntax"),
    ],
)
def test_bad_mapping_files(tmp_path: Path, old: str, new: str, word: str) -> None:
    path = _user_mapping(tmp_path, old, new)
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    assert "my_mapping.yaml" in str(info.value) and word in str(info.value)


def test_unknown_mapping_name() -> None:
    with pytest.raises(MappingError, match="did you mean 'cmu'"):
        load_mapping("cmuu")


def test_rotations16_from_cmu(walk: dict[str, np.ndarray]) -> None:
    """ROTATIONS derived from a CMU clip: identity = T-pose, legs reproduce the clip exactly."""
    from tbha_graph.mocap.io.skeleton_map import rotations16_from_bvh
    from tbha_graph.mocap.kinematics import forward_kinematics
    from tbha_graph.mocap.skeleton import PARENTS, TPOSE_DIRECTIONS

    rot = rotations16_from_bvh(CMU / "131_02.bvh")
    assert rot["local_quat"].shape == (720, 16, 4) and float(rot["fps"]) == pytest.approx(120, rel=1e-4)
    fk = forward_kinematics(PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])[0]
    err_mm = np.linalg.norm(fk - walk["joints"], axis=-1) * 1000
    legs = [JOINT_INDEX[n] for n in ("hips", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")]
    assert err_mm[:, legs].max() < 1e-6
    # the upper body follows the clip up to the spine bend the 16-joint model cannot represent
    assert err_mm.max() < 80
    # limb bones lie along their T-pose directions in the rest offsets
    for name in ("left_elbow", "left_wrist", "right_elbow", "right_wrist", "left_knee", "left_ankle"):
        j = JOINT_INDEX[name]
        assert np.dot(rot["offsets"][j], TPOSE_DIRECTIONS[j]) / np.linalg.norm(rot["offsets"][j]) > 0.9999
    assert rot["end_offsets"][JOINT_INDEX["left_ankle"], 2] > 0.1  # the foot points forward (+z)
