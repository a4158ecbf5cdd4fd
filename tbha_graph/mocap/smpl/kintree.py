"""The SMPL kinematic tree (24 joints) and how the 16 TBHA joints drive it.

SMPL's rest pose is a T-pose in metres, y up, facing +z, the left arm along +x: the same axes as the project's
world frame and its rest T-pose (:mod:`tbha_graph.mocap.skeleton`). Pose parameters are, per joint, the
axis-angle rotation relative to the parent, expressed in the rest pose's (world-aligned) axes; joint 0's is
the global orientation.
"""
from __future__ import annotations

import numpy as np

SMPL_JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)
N_SMPL_JOINTS = len(SMPL_JOINT_NAMES)
SMPL_INDEX: dict[str, int] = {n: i for i, n in enumerate(SMPL_JOINT_NAMES)}

#: Parent index of each SMPL joint (-1 for the pelvis), shape (24,).
SMPL_PARENTS: np.ndarray = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21], dtype=np.int64
)

#: Number of pose blend shape features: 23 non-root joints x 9 rotation-matrix entries.
N_POSE_FEATURES = (N_SMPL_JOINTS - 1) * 9

#: SMPL joint -> the TBHA joint whose rotation it takes (the joint rotating the same body segment).
#: SMPL joints not listed stay at rest relative to their parent (collars, hands, feet), except the three
#: spine joints, which share the chest's rotation relative to the hips (see :mod:`.pose`).
SMPL_FROM_TBHA: dict[str, str] = {
    "pelvis": "hips",
    "neck": "neck",
    "head": "head",
    "left_shoulder": "left_shoulder", "right_shoulder": "right_shoulder",
    "left_elbow": "left_elbow", "right_elbow": "right_elbow",
    "left_wrist": "left_wrist", "right_wrist": "right_wrist",
    "left_hip": "left_hip", "right_hip": "right_hip",
    "left_knee": "left_knee", "right_knee": "right_knee",
    "left_ankle": "left_ankle", "right_ankle": "right_ankle",
}
SPINE_JOINTS: tuple[str, ...] = ("spine1", "spine2", "spine3")

#: Limb segments whose rest direction may differ between SMPL's template and the TBHA T-pose:
#: SMPL joint -> (SMPL child joint, TBHA child joint). Used to align rest bone directions when a model is given.
LIMB_SEGMENTS: dict[str, tuple[str, str]] = {
    "left_shoulder": ("left_elbow", "left_elbow"), "right_shoulder": ("right_elbow", "right_elbow"),
    "left_elbow": ("left_wrist", "left_wrist"), "right_elbow": ("right_wrist", "right_wrist"),
    "left_hip": ("left_knee", "left_knee"), "right_hip": ("right_knee", "right_knee"),
    "left_knee": ("left_ankle", "left_ankle"), "right_knee": ("right_ankle", "right_ankle"),
}
