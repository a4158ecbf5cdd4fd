"""Write the bundled example character skeletons ``data/characters/*.bvh`` (run: ``python -m
tbha_graph.mocap.retarget.make_characters [out_dir]``).

Each character is built here from a few body measurements (metres) and directions, then written as a
BVH hierarchy with one rest frame (root at its standing height, every rotation zero):

* ``mixamo_like_apose.bvh``: Mixamo-style names (``mixamorig:Hips``, ``Spine``, ``Spine1``, ``Spine2``,
  clavicles ``LeftShoulder``, ``LeftArm`` ..., index finger and thumb joints, toes), centimetres, y up,
  facing +z, rest in an **A-pose** (upper arms and forearms 45 degrees below horizontal), a tall adult
  (1.82 m) with long legs and a three-joint spine. Retarget onto it with mapping ``mixamo``.
* ``child.bvh``: CMU-style names (``Hips``, ``LHipJoint``, ``LeftHip`` ..., ``lowerback``, ``Chest``,
  ``Chest2``, ``lowerneck``, ``Neck``, ``Head``, ``LeftCollar`` ...), CMU units (1 unit = 0.05644 m, as
  the bundled ``cmu`` mapping expects), y up, facing +z, rest in a T-pose, a 1.19 m child (shorter legs
  and a larger head relative to the body). Retarget onto it with mapping ``cmu``.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.bvh import POSITION_CHANNELS, Bvh, BvhJoint, write_bvh

#: metres per CMU unit (the bundled ``cmu`` mapping's ``units_to_metres``)
CMU_UNIT_M = 0.05644


@dataclass
class Bone:
    """A joint ``name`` under ``parent`` at ``offset`` (3,) metres from it; ``end`` (3,) End Site or None."""

    name: str
    parent: str | None
    offset: tuple[float, float, float]
    end: tuple[float, float, float] | None = None


def _along(direction: np.ndarray, length: float) -> tuple[float, float, float]:
    d = np.asarray(direction, dtype=np.float64)
    return tuple(float(x) for x in d / np.linalg.norm(d) * length)


def _mirror(bones: list[Bone], rename: dict[str, str]) -> list[Bone]:
    """Right-side copies of left-side bones: x negated, names changed by the substring pairs ``rename``."""

    def name(s: str | None) -> str | None:
        if s is None:
            return None
        for a, b in rename.items():
            s = s.replace(a, b)
        return s

    def flip(v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        return None if v is None else (-v[0], v[1], v[2])

    return [Bone(name(b.name), name(b.parent), flip(b.offset), flip(b.end)) for b in bones]


def standing_height(bones: list[Bone]) -> float:
    """Height (metres) of the root above the lowest point of the rest pose (joints and End Sites)."""
    pos: dict[str, np.ndarray] = {}
    lowest = 0.0
    for b in bones:  # parents are listed before their children
        pos[b.name] = (pos[b.parent] if b.parent else np.zeros(3)) + np.asarray(b.offset)
        lowest = min(lowest, pos[b.name][1], pos[b.name][1] + (b.end[1] if b.end else 0.0))
    return -lowest


def mixamo_like_apose() -> list[Bone]:
    """Bones of the Mixamo-like A-pose character (metres)."""
    p = "mixamorig:"
    arm = np.array([np.cos(np.radians(45.0)), -np.sin(np.radians(45.0)), 0.0])  # left arm, 45 deg down
    spine = [
        Bone(f"{p}Spine", f"{p}Hips", (0.0, 0.100, 0.010)),
        Bone(f"{p}Spine1", f"{p}Spine", (0.0, 0.120, 0.000)),
        Bone(f"{p}Spine2", f"{p}Spine1", (0.0, 0.140, -0.010)),
        Bone(f"{p}Neck", f"{p}Spine2", (0.0, 0.160, 0.010)),
        Bone(f"{p}Head", f"{p}Neck", (0.0, 0.100, 0.020), end=(0.0, 0.170, 0.015)),
    ]
    left_arm = [
        Bone(f"{p}LeftShoulder", f"{p}Spine2", (0.060, 0.110, 0.000)),
        Bone(f"{p}LeftArm", f"{p}LeftShoulder", (0.130, 0.000, 0.000)),
        Bone(f"{p}LeftForeArm", f"{p}LeftArm", _along(arm, 0.290)),
        Bone(f"{p}LeftHand", f"{p}LeftForeArm", _along(arm, 0.260)),
        Bone(f"{p}LeftHandIndex1", f"{p}LeftHand", _along(arm, 0.090)),
        Bone(f"{p}LeftHandIndex2", f"{p}LeftHandIndex1", _along(arm, 0.040)),
        Bone(f"{p}LeftHandIndex3", f"{p}LeftHandIndex2", _along(arm, 0.030), end=_along(arm, 0.025)),
        Bone(f"{p}LeftHandThumb1", f"{p}LeftHand", _along(arm + [0.0, 0.0, 1.0], 0.035)),
        Bone(f"{p}LeftHandThumb2", f"{p}LeftHandThumb1", _along(arm + [0.0, 0.0, 0.6], 0.035),
             end=_along(arm + [0.0, 0.0, 0.4], 0.030)),
    ]
    left_leg = [
        Bone(f"{p}LeftUpLeg", f"{p}Hips", (0.095, -0.070, 0.000)),
        Bone(f"{p}LeftLeg", f"{p}LeftUpLeg", (0.000, -0.460, 0.005)),
        Bone(f"{p}LeftFoot", f"{p}LeftLeg", (0.000, -0.440, -0.020)),
        Bone(f"{p}LeftToeBase", f"{p}LeftFoot", (0.000, -0.060, 0.130), end=(0.000, 0.000, 0.080)),
    ]
    bones = [Bone(f"{p}Hips", None, (0.0, 0.0, 0.0))] + spine + left_arm
    bones += _mirror(left_arm, {"Left": "Right"}) + left_leg + _mirror(left_leg, {"Left": "Right"})
    return bones


def child() -> list[Bone]:
    """Bones of the CMU-like child, T-pose (metres)."""
    x = np.array([1.0, 0.0, 0.0])
    left_leg = [
        Bone("LHipJoint", "Hips", (0.0, 0.0, 0.0)),
        Bone("LeftHip", "LHipJoint", (0.065, -0.055, 0.010)),
        Bone("LeftKnee", "LeftHip", (0.0, -0.290, 0.0)),
        Bone("LeftAnkle", "LeftKnee", (0.0, -0.270, 0.0)),
        Bone("LeftToe", "LeftAnkle", (0.0, -0.040, 0.090), end=(0.0, 0.0, 0.040)),
    ]
    spine = [
        Bone("lowerback", "Hips", (0.0, 0.0, 0.0)),
        Bone("Chest", "lowerback", (0.0, 0.080, 0.005)),
        Bone("Chest2", "Chest", (0.0, 0.150, 0.005)),
        Bone("lowerneck", "Chest2", (0.0, 0.0, 0.0)),
        Bone("Neck", "lowerneck", (0.0, 0.060, 0.005)),
        Bone("Head", "Neck", (0.0, 0.070, 0.010), end=(0.0, 0.170, 0.0)),
    ]
    left_arm = [
        Bone("LeftCollar", "Chest2", (0.0, 0.0, 0.0)),
        Bone("LeftShoulder", "LeftCollar", (0.125, 0.045, 0.0)),
        Bone("LeftElbow", "LeftShoulder", _along(x, 0.180)),
        Bone("LeftWrist", "LeftElbow", _along(x, 0.160)),
        Bone("lhand", "LeftWrist", _along(x, 0.040)),
        Bone("LFingers", "lhand", _along(x, 0.040), end=_along(x, 0.030)),
        Bone("LThumb", "lhand", _along(x + [0.0, 0.0, 1.0], 0.030), end=_along(x + [0.0, 0.0, 1.0], 0.025)),
    ]
    bones = [Bone("Hips", None, (0.0, 0.0, 0.0))] + left_leg + _mirror(left_leg, {"LHip": "RHip", "Left": "Right"})
    bones += spine + left_arm + _mirror(left_arm, {"Left": "Right", "lhand": "rhand", "LFingers": "RFingers", "LThumb": "RThumb"})
    return bones


def to_bvh(bones: list[Bone], units_per_metre: float, root_order: str, order: str) -> Bvh:
    """A one-frame BVH of ``bones`` in file units, standing on y = 0 (every rotation zero)."""
    index = {b.name: i for i, b in enumerate(bones)}
    # depth-first order, children in the order given
    kids: dict[str | None, list[Bone]] = {}
    for b in bones:
        kids.setdefault(b.parent, []).append(b)
    ordered: list[Bone] = []

    def visit(b: Bone) -> None:
        ordered.append(b)
        for c in kids.get(b.name, []):
            visit(c)

    (root,) = kids[None]
    visit(root)
    if len(ordered) != len(bones) or len(index) != len(bones):
        raise ValueError("bones do not form one tree with unique names")
    pos = {b.name: i for i, b in enumerate(ordered)}
    joints = []
    for b in ordered:
        rot = tuple(f"{a}rotation" for a in (root_order if b.parent is None else order))
        chans = POSITION_CHANNELS + rot if b.parent is None else rot
        end = None if b.end is None else np.asarray(b.end) * units_per_metre
        joints.append(BvhJoint(b.name, -1 if b.parent is None else pos[b.parent],
                               np.asarray(b.offset) * units_per_metre, chans, end))
    motion = np.zeros((1, 3 + 3 * len(joints)))
    motion[0, 1] = standing_height(ordered) * units_per_metre
    return Bvh(joints=joints, frame_time=1.0 / 30.0, motion=motion)


def main(out_dir: str | Path | None = None) -> list[Path]:
    """Write both characters into ``out_dir`` (default: the repository's ``data/characters``)."""
    out = Path(out_dir) if out_dir else Path(__file__).resolve().parents[3] / "data" / "characters"
    out.mkdir(parents=True, exist_ok=True)
    a = write_bvh(out / "mixamo_like_apose.bvh", to_bvh(mixamo_like_apose(), 100.0, "ZXY", "ZXY"), precision=4)
    b = write_bvh(out / "child.bvh", to_bvh(child(), 1.0 / CMU_UNIT_M, "ZYX", "ZXY"), precision=5)
    return [a, b]


if __name__ == "__main__":
    for path in main(sys.argv[1] if len(sys.argv) > 1 else None):
        print(path)
