"""The TBHA 16-joint body model: the one place joint names, order and hierarchy are defined.

Conventions used across the whole mocap package (see also :mod:`tbha_graph.mocap.camera`):

* World frame: metres, right-handed, **y up**. In the rest T-pose the actor faces **+z**,
  so the actor's left side is **+x**.
* Joint arrays have shape ``(n_frames, N_JOINTS, 3)`` (positions) or ``(n_frames, N_JOINTS, 2)``
  (pixels), with joints in the order of :data:`JOINT_NAMES`.
* The names below are used verbatim everywhere, BVH files included (``ROOT hips``).
"""
from __future__ import annotations

import numpy as np

#: Joint names in array order. Index 0 is the root (pelvis / abdomen, the seed's "hip").
JOINT_NAMES: tuple[str, ...] = (
    "hips",
    "chest",
    "neck",
    "head",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
)
N_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

#: Parent of each joint by name (root has None).
PARENT_NAMES: dict[str, str | None] = {
    "hips": None,
    "chest": "hips",
    "neck": "chest",
    "head": "neck",
    "left_shoulder": "chest",
    "left_elbow": "left_shoulder",
    "left_wrist": "left_elbow",
    "right_shoulder": "chest",
    "right_elbow": "right_shoulder",
    "right_wrist": "right_elbow",
    "left_hip": "hips",
    "left_knee": "left_hip",
    "left_ankle": "left_knee",
    "right_hip": "hips",
    "right_knee": "right_hip",
    "right_ankle": "right_knee",
}
#: Parent index of each joint (``-1`` for the root), shape ``(N_JOINTS,)``.
PARENTS: np.ndarray = np.array(
    [-1 if PARENT_NAMES[n] is None else JOINT_INDEX[PARENT_NAMES[n]] for n in JOINT_NAMES], dtype=np.int64
)
#: Children of each joint, by index.
CHILDREN: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(c) for c in np.flatnonzero(PARENTS == j)) for j in range(N_JOINTS)
)
#: Bones as (parent index, child index) pairs, shape ``(N_JOINTS - 1, 2)``.
BONES: np.ndarray = np.array([(int(PARENTS[j]), j) for j in range(1, N_JOINTS)], dtype=np.int64)

#: Joints that carry a coloured patch on the suit (all but the head, whose dark hair is its "patch").
PATCHED_JOINTS: tuple[str, ...] = tuple(n for n in JOINT_NAMES if n != "head")
N_PATCHES = len(PATCHED_JOINTS)

#: The torso's seven points (near-rigid: hips, spine, shoulders, hip joints), whose suit patches fix the torso's
#: turn and depth; by name and as indices into :data:`JOINT_NAMES`.
TORSO_JOINT_NAMES: tuple[str, ...] = ("hips", "chest", "neck", "left_shoulder", "right_shoulder", "left_hip", "right_hip")
TORSO_JOINTS: np.ndarray = np.array([JOINT_INDEX[n] for n in TORSO_JOINT_NAMES], dtype=np.int64)


def torso_unseen(weight: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: frames where fewer than 3 of the torso's 7 points are tracked (``weight`` ``(n, 16)``: bool
    tracked flags or weights, 0 = not tracked): the image does not fix the torso's turn or depth there (the
    suit's patches are on the body's front: the actor's back to the camera, or the torso hidden)."""
    return (np.asarray(weight)[:, TORSO_JOINTS] > 0).sum(axis=1) < 3


#: The five torso points the coplanar Tsai calibration uses (seed 000, section 3.1).
CALIBRATION_JOINTS: tuple[str, ...] = ("neck", "chest", "hips", "left_shoulder", "right_shoulder")

#: The stable triangle the 3D reconstruction starts from (seed 000, section 3.2).
TRIANGLE_JOINTS: tuple[str, ...] = ("chest", "left_shoulder", "right_shoulder")

#: Default bone lengths in metres (child joint name -> length of the bone from its parent), used when
#: the user gives no measurements: the left/right averages of CMU subject 131 mapped onto this model
#: (hips = pelvis root, chest = upper chest, neck = neck base, head = skull base; see data/mocap).
DEFAULT_BONE_LENGTHS: dict[str, float] = {
    "chest": 0.224,
    "neck": 0.091,
    "head": 0.090,
    "left_shoulder": 0.184,
    "left_elbow": 0.246,
    "left_wrist": 0.190,
    "right_shoulder": 0.184,
    "right_elbow": 0.246,
    "right_wrist": 0.190,
    "left_hip": 0.122,
    "left_knee": 0.409,
    "left_ankle": 0.392,
    "right_hip": 0.122,
    "right_knee": 0.409,
    "right_ankle": 0.392,
}

#: Unit direction of each bone (parent -> joint) in the rest T-pose, world frame, shape ``(N_JOINTS, 3)``.
#: Row 0 (root) is zero. Arms point sideways (+x for the left arm), legs down, spine up; the shoulder
#: joints sit up and out from the chest patch, the hip joints down and out from the pelvis.
_TPOSE_DIRS = {
    "hips": (0.0, 0.0, 0.0),
    "chest": (0.0, 1.0, 0.0),
    "neck": (0.0, 1.0, 0.0),
    "head": (0.0, 1.0, 0.0),
    "left_shoulder": (0.9, 0.43, 0.0),
    "left_elbow": (1.0, 0.0, 0.0),
    "left_wrist": (1.0, 0.0, 0.0),
    "right_shoulder": (-0.9, 0.43, 0.0),
    "right_elbow": (-1.0, 0.0, 0.0),
    "right_wrist": (-1.0, 0.0, 0.0),
    "left_hip": (0.6, -0.8, 0.0),
    "left_knee": (0.0, -1.0, 0.0),
    "left_ankle": (0.0, -1.0, 0.0),
    "right_hip": (-0.6, -0.8, 0.0),
    "right_knee": (0.0, -1.0, 0.0),
    "right_ankle": (0.0, -1.0, 0.0),
}
TPOSE_DIRECTIONS: np.ndarray = np.array([_TPOSE_DIRS[n] for n in JOINT_NAMES], dtype=np.float64)
_norm = np.linalg.norm(TPOSE_DIRECTIONS, axis=1, keepdims=True)
TPOSE_DIRECTIONS = np.divide(TPOSE_DIRECTIONS, _norm, out=np.zeros_like(TPOSE_DIRECTIONS), where=_norm > 0)


def topological_order() -> tuple[int, ...]:
    """Joint indices ordered so that every parent comes before its children (root first)."""
    order: list[int] = []
    stack = [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(CHILDREN[j]))
    return tuple(order)


def bone_lengths_array(lengths: dict[str, float] | None = None) -> np.ndarray:
    """Bone lengths as an array of shape ``(N_JOINTS,)`` metres, entry ``j`` = |joint j - parent(j)|.

    Entry 0 (root) is 0. Missing names fall back to :data:`DEFAULT_BONE_LENGTHS`.
    Raises ``KeyError`` naming an unknown joint.
    """
    merged = dict(DEFAULT_BONE_LENGTHS)
    for name, value in (lengths or {}).items():
        if name not in JOINT_INDEX or name == "hips":
            raise KeyError(f"unknown bone {name!r}: bones are named by their child joint, one of {JOINT_NAMES[1:]}")
        merged[name] = float(value)
    out = np.zeros(N_JOINTS)
    for name, value in merged.items():
        out[JOINT_INDEX[name]] = value
    return out


def measure_bone_lengths(joints: np.ndarray) -> np.ndarray:
    """Bone lengths measured from positions ``(..., N_JOINTS, 3)``; returns ``(..., N_JOINTS)`` (root 0)."""
    joints = np.asarray(joints, dtype=np.float64)
    parent = np.where(PARENTS < 0, 0, PARENTS)
    d = np.linalg.norm(joints - joints[..., parent, :], axis=-1)
    d[..., 0] = 0.0
    return d


def tpose(lengths: np.ndarray | None = None, root: tuple[float, float, float] = (0.0, 0.95, 0.0)) -> np.ndarray:
    """Joint positions ``(N_JOINTS, 3)`` metres, world frame, of the rest T-pose facing +z."""
    lengths = bone_lengths_array() if lengths is None else np.asarray(lengths, dtype=np.float64)
    pos = np.zeros((N_JOINTS, 3))
    pos[0] = root
    for j in topological_order()[1:]:
        pos[j] = pos[PARENTS[j]] + lengths[j] * TPOSE_DIRECTIONS[j]
    return pos
