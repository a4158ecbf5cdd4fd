"""Rest-pose alignment between the capture's skeleton and a character, and the root scale factor.

Both rest poses have every joint rotation at identity, but the bones need not point the same way (the
capture rests in a T-pose, a character may rest in an A-pose with the arms ~45 degrees down). For each
of the 16 joints ``j`` the alignment ``A[j]`` is the world rotation taking the character's rest
directions of ``j``'s outgoing bones onto the capture's rest directions, so that the character joint
given world rotation ``W[j] * A[j]`` (``W``: the capture's world rotation) points its bones where the
capture's bones point. Positions are world metres, y up, facing +z; quaternions xyzw.

* one outgoing bone (neck, shoulders, elbows, hip joints, knees): the shortest arc between the two
  rest directions (no twist about the bone is introduced);
* ``hips`` and ``chest`` (three outgoing bones): the spine direction (to chest / neck) exactly and the
  left-right axis (between the hip joints / shoulders) as closely as possible
  (:func:`tbha_graph.mocap.quat.rotation_from_pairs`);
* leaves (head, wrists, ankles: no bone beyond them in the capture): the parent's alignment, so a leaf
  at rest relative to its parent in the capture is at rest relative to its parent on the character.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import forward_kinematics
from ..quat import rotation_from_pairs, shortest_arc
from ..skeleton import CHILDREN, JOINT_INDEX, N_JOINTS, PARENTS

_HIPS, _CHEST = JOINT_INDEX["hips"], JOINT_INDEX["chest"]
#: for the two branching joints: (spine child, left joint, right joint) of the left-right axis
_TORSO = {
    _HIPS: (JOINT_INDEX["chest"], JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]),
    _CHEST: (JOINT_INDEX["neck"], JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]),
}
_ANKLES = (JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"])


def rest_positions16(offsets: np.ndarray) -> np.ndarray:
    """Rest positions (16, 3) of the 16-joint skeleton with ``offsets`` (16, 3), root at the origin."""
    ident = np.tile([0.0, 0.0, 0.0, 1.0], (1, N_JOINTS, 1))
    return forward_kinematics(PARENTS, offsets, ident, np.zeros((1, 3)))[0][0]


def rest_alignment(source_rest: np.ndarray, target_rest: np.ndarray) -> np.ndarray:
    """Alignment rotations ``A`` (16, 4) xyzw taking the target's rest bone directions to the source's.

    ``source_rest``, ``target_rest``: rest positions (16, 3) of the 16 joints (the target's are its
    mapped joints), world axes, any scale.
    """
    a = np.tile([0.0, 0.0, 0.0, 1.0], (N_JOINTS, 1))
    order = [j for j in range(N_JOINTS)]  # parents come before children in JOINT_NAMES
    for j in order:
        kids = CHILDREN[j]
        if j in _TORSO:
            spine, left, right = _TORSO[j]
            a[j] = rotation_from_pairs(
                target_rest[spine] - target_rest[j], target_rest[left] - target_rest[right],
                source_rest[spine] - source_rest[j], source_rest[left] - source_rest[right],
            )
        elif len(kids) == 1:
            c = kids[0]
            a[j] = shortest_arc(target_rest[c] - target_rest[j], source_rest[c] - source_rest[j])
        else:  # a leaf: keep its rest relation to the parent
            a[j] = a[PARENTS[j]]
    return a


def leg_height(rest: np.ndarray) -> float:
    """Rest height (metres) of the hips above the mean of the two ankles, from rest positions (16, 3):
    the hip-to-ankle leg length the root translation is scaled by."""
    return float(rest[_HIPS, 1] - rest[list(_ANKLES), 1].mean())
