"""``rotations.quaternion``: joint rotations from 3D positions with quaternions (seed 002), the default.

Per frame and joint, vectorised over both (see :mod:`.common` for the conventions and the hinge
refinement, :mod:`.rest` for the rest skeleton):

* ``hips`` and ``chest`` (three children, full orientation): seed 002 "with reference points" —
  :func:`.quat.rotation_from_pairs` from the rest to the current lateral and reference vectors
  (the axis from the two perpendicular-bisector planes, the angle from the perpendicular components).
* neck, shoulders, elbows, hip joints, knees (one child, direction only): seed 002 "no reference
  point" — the shortest arc from the rest to the current bone direction.
* elbows/knees as hinges and upper arm/thigh twist from the limb plane: seed 002 axis limits.
* head, wrists, ankles: local identity.
* then (``torso_fit``, default) the hips' position and the hips' and chest's rotations refined frame by frame so
  that all 16 joints land as close to the motion's as the rigid torso allows (:mod:`.torso_fit`): the reference
  vectors above are its start.

Output: the ROTATIONS bundle (``local_quat`` xyzw relative to the parent, identity in the rest T-pose,
continuous in time; ``root_position`` = the hips trajectory, moved by the torso fit; constant ``offsets`` from median bone
lengths; ``end_offsets``; ``fps``). Never NaN: degenerate geometry (straight limbs, zero-length bones,
collinear torso points) falls back as documented in :mod:`.quat`.
"""
from __future__ import annotations

import numpy as np

from ...core.node import node
from ..bundles.motion import motion_joints
from ..ports import MOTION, ROTATIONS
from .common import SolverParams, empty_world, pose_from_torso, rest_skeleton, rotations_bundle
from ..quat import rotation_from_pairs
from .rest import TORSO, TorsoReference, rest_points, torso_vectors
from .torso_fit import fit_torso


class QuaternionParams(SolverParams):
    """Parameters of ``rotations.quaternion`` (all shared with ``rotations.kabsch``)."""


def torso_rotations(joints: np.ndarray, offsets: np.ndarray, references: dict[int, TorsoReference]) -> dict[int, np.ndarray]:
    """World rotations ``(n, 4)`` of ``hips`` and ``chest`` by the seed's reference-point method,
    ``references``: torso joint index -> ``"spine"`` or ``"triangle"`` (see :mod:`.rest`)."""
    out = {}
    for j in TORSO:
        u1, u2 = torso_vectors(rest_points(offsets, j), j, references[j])
        v1, v2 = torso_vectors(joints, j, references[j])
        out[j] = rotation_from_pairs(u1, u2, v1, v2, exact_first=True)
    return out


def quaternion_rotations(joints: np.ndarray, fps: float, params: SolverParams | None = None) -> dict[str, np.ndarray]:
    """The ROTATIONS bundle for positions ``joints`` ``(n, 16, 3)`` metres (finite) at ``fps``."""
    p = params or QuaternionParams()
    joints = np.asarray(joints, dtype=np.float64)
    _, offsets = rest_skeleton(joints, p)
    world = empty_world(joints.shape[0])
    for j, q in torso_rotations(joints, offsets, p.references).items():
        world[:, j] = q
    if p.torso_fit:
        world, joints = fit_torso(world, joints, offsets, p)
    return rotations_bundle(pose_from_torso(world, joints, offsets, p), joints, offsets, fps, p)


@node("rotations.quaternion", version=3, inputs={"motion": MOTION}, outputs={"rotations": ROTATIONS}, params=QuaternionParams)
def quaternion(ctx, motion):
    """Joint rotations (BVH-ready) from 3D joint positions by the seed 002 quaternion method with hinge limits."""
    joints, fps = motion_joints(motion)
    return {"rotations": quaternion_rotations(joints, fps, ctx.params)}
