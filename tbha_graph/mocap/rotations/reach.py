"""Knees bent so the ankles land where the motion's are, from where the rigid pelvis puts the hip joints.

The skeleton's torso is rigid (one rotation each for ``hips`` and ``chest``, constant rest offsets); a motion's
torso is not (a real lumbar spine bends, a solver's pelvis folds against its spine), so the torso rotations place
the hip joints a little off the motion's. Swinging thigh and shin to the motion's directions from there moves
the whole leg by that miss, the foot included: on the bundled sample the solver's leg joints came out 29 mm off in
the BVH, a foot 18 mm below the floor and sliding more (foot skate 3.2 mm a frame against the solver's 2.6).
Instead each leg (hip-knee-ankle, :data:`LEGS`) is re-placed by two-bone inverse kinematics: its hip joint where
the rigid pelvis puts it, its ankle on the motion's, its knee on the circle the two bone lengths allow, in the
plane of the motion's own bend (:func:`tbha_graph.mocap.kinematics.two_bone_ik`; a straight leg bends forwards,
where the pelvis faces). An ankle beyond reach is approached along the straight leg. The arms are left swung: the
chest's reference (the shoulder line) already puts the shoulders on the motion's, and nothing a hand touches is
known.

Positions ``(n, 16, 3)`` metres, world frame; rotations xyzw ``(n, 16, 4)``.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import two_bone_ik
from ..quat import quat_apply
from ..skeleton import PARENTS
from .rest import HINGES

#: The legs' chains ``(hip joint, knee, ankle, hinge axis)``, from :data:`.rest.HINGES`
LEGS = tuple(h for h in HINGES if PARENTS[h[0]] == 0)


def reach_feet(world: np.ndarray, joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """``joints`` ``(n, 16, 3)`` with each leg re-placed (module docstring): its hip joint where the torso rotations
    ``world`` ``(n, 16, 4)`` and rest ``offsets`` ``(16, 3)`` put it, its knee and ankle by two-bone IK to the
    motion's ankle (bone lengths of ``offsets``) on the frames where that hip joint is not the motion's, every other
    joint as it is: what the limbs' swings are taken from."""
    out = joints.copy()
    lengths = np.linalg.norm(offsets, axis=-1)
    forward = quat_apply(world[:, 0], np.array([0.0, 0.0, 1.0]))  # the rest T-pose faces +z
    for hip, knee, ankle, _ in LEGS:
        placed = joints[:, 0] + quat_apply(world[:, 0], offsets[hip])  # where the pelvis's rotation puts it
        f = np.flatnonzero(np.linalg.norm(placed - joints[:, hip], axis=-1) > 1e-9)  # elsewhere the swing is exact
        out[f, hip] = placed[f]
        out[f, knee], out[f, ankle], _ = two_bone_ik(placed[f], joints[f, knee], joints[f, ankle], joints[f, ankle],
                                                     forward[f], (lengths[knee], lengths[ankle]))
    return out
