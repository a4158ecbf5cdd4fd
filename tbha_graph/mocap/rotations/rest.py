"""The rest skeleton the rotations are relative to: offsets, End Sites, torso reference vectors.

Rest pose: the T-pose facing +z (:data:`tbha_graph.mocap.skeleton.TPOSE_DIRECTIONS`), every bone at
its median length over the clip, so one constant ``offsets`` array serves all frames.

Two joints have several children and get a full orientation (seed 002 "with reference points"):
``hips`` (children chest, left_hip, right_hip) and ``chest`` (neck, left_shoulder, right_shoulder).
Each uses two reference vectors, a primary one matched exactly and a secondary one fixing the turn
about it (see :func:`.quat.rotation_from_pairs`), chosen per joint:

* ``"spine"``: primary = to the spine child (chest for hips, neck for chest), secondary = the
  lateral vector (left child minus right child). The spine child's position is exact.
* ``"triangle"``: primary = the lateral vector, secondary = to the midpoint of the lateral pair, so
  only the triangle (hips, left_hip, right_hip) or (chest, left_shoulder, right_shoulder) — the
  seed 000 "stable triangle" — decides; the lateral pair's positions are exact (when the triangle is rigid).

Real torsos are not rigid: CMU subject 131 bends its lumbar spine by 8 degrees on average (15 at most)
relative to its pelvis while walking, its neck 2 degrees relative to the shoulder line. A 16-joint
skeleton has one rigid segment for each, so that bend appears as a position error of the joints on
the side that is not matched exactly. Defaults (``hips: spine``, ``chest: triangle``) match the side
that carries more joints (the upper body over the legs, the arms over the head).

``torso_rest="measured"`` (default) takes the rest offsets of these six children from the clip: the
median of each child's offset expressed in its parent's torso frame (primary axis, secondary axis made
perpendicular, their cross product), rescaled to the median bone length. The rest pose is then still a
T-pose facing +z (arms and legs along the T-pose directions, the torso frame that of the T-pose) but
with the actor's own torso proportions, so real positions are reproduced as closely as a rigid torso
allows. ``torso_rest="tpose"`` uses the T-pose directions for every bone.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from ..skeleton import JOINT_INDEX, N_JOINTS, PARENTS, TPOSE_DIRECTIONS
from ..quat import unit

TorsoRest = Literal["measured", "tpose"]
TorsoReference = Literal["triangle", "spine"]

_J = JOINT_INDEX
#: joint -> (left child, right child, spine child) for the joints with a full orientation
TORSO: dict[int, tuple[int, int, int]] = {
    _J["hips"]: (_J["left_hip"], _J["right_hip"], _J["chest"]),
    _J["chest"]: (_J["left_shoulder"], _J["right_shoulder"], _J["neck"]),
}

#: default reference of each torso joint (see module doc)
DEFAULT_REFERENCES: dict[int, TorsoReference] = {_J["hips"]: "spine", _J["chest"]: "triangle"}

#: hinge limbs (upper joint, hinge joint, end joint) and the hinge axis in the upper joint's rest frame:
#: the axis a positive (flexing) rotation of the hinge joint turns about. Elbows flex forward (+z) from
#: the T-pose, knees flex backward (-z); all four are perpendicular to their limb's rest direction.
HINGES: tuple[tuple[int, int, int, tuple[float, float, float]], ...] = (
    (_J["left_shoulder"], _J["left_elbow"], _J["left_wrist"], (0.0, -1.0, 0.0)),
    (_J["right_shoulder"], _J["right_elbow"], _J["right_wrist"], (0.0, 1.0, 0.0)),
    (_J["left_hip"], _J["left_knee"], _J["left_ankle"], (1.0, 0.0, 0.0)),
    (_J["right_hip"], _J["right_knee"], _J["right_ankle"], (1.0, 0.0, 0.0)),
)

#: leaf joints (no children): head, wrists, ankles
LEAVES: tuple[int, ...] = tuple(j for j in range(N_JOINTS) if not np.any(PARENTS == j))
#: the ankles, whose End Site is a foot pointing forward (+z) instead of continuing the shin
FEET: tuple[int, ...] = (_J["left_ankle"], _J["right_ankle"])


def torso_vectors(points: np.ndarray, joint: int, reference: TorsoReference) -> tuple[np.ndarray, np.ndarray]:
    """Primary and secondary reference vectors ``(..., 3)`` of torso ``joint`` (see module doc) from
    positions ``(..., 16, 3)`` (or from rest offsets ``(16, 3)`` with the joint at the origin)."""
    left, right, spine = TORSO[joint]
    lateral = points[..., left, :] - points[..., right, :]
    if reference == "spine":
        return points[..., spine, :] - points[..., joint, :], lateral
    return lateral, 0.5 * (points[..., left, :] + points[..., right, :]) - points[..., joint, :]


def torso_frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(..., 3, 3)`` (columns: primary axis, secondary axis made perpendicular to
    it, their cross product), from vectors ``(..., 3)``. Degenerate input gives a zero column."""
    x, _ = unit(primary)
    y, _ = unit(secondary - np.sum(secondary * x, axis=-1, keepdims=True) * x)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def rest_offsets(
    joints: np.ndarray, lengths: np.ndarray, torso_rest: TorsoRest = "measured", references: dict[int, TorsoReference] | None = None
) -> np.ndarray:
    """Rest offsets ``(16, 3)`` metres from positions ``(n, 16, 3)`` and bone lengths ``(16,)``.

    Limbs, neck and head follow the T-pose directions; the children of ``hips`` and ``chest`` too with
    ``torso_rest="tpose"``, else their median direction in the parent's torso frame (see module doc).
    A child whose measured direction is zero keeps its T-pose direction.
    """
    lengths = np.asarray(lengths, dtype=np.float64)
    offsets = lengths[:, None] * TPOSE_DIRECTIONS
    if torso_rest == "tpose":
        return offsets
    refs = {**DEFAULT_REFERENCES, **(references or {})}
    for joint, children in TORSO.items():
        torso_reference = refs[joint]
        # the torso frame of the T-pose: measured directions are expressed in it
        tpose_frame = torso_frame(*torso_vectors(rest_points(offsets, joint), joint, torso_reference))
        frame = torso_frame(*torso_vectors(joints, joint, torso_reference))  # (n, 3, 3)
        good = np.abs(np.linalg.det(frame)) > 0.5
        if not good.any() or abs(np.linalg.det(tpose_frame)) < 0.5:
            continue
        for c in children:
            local = np.einsum("nij,ni->nj", frame[good], joints[good, c] - joints[good, joint])
            d, norm = unit(tpose_frame @ np.median(local, axis=0))
            if norm > 0:
                offsets[c] = lengths[c] * d
        # medians are per component: turn the three offsets together so that their torso frame is
        # exactly the T-pose's (the rest pose faces +z with the lateral axis along x)
        rest = torso_frame(*torso_vectors(rest_points(offsets, joint), joint, torso_reference))
        if abs(np.linalg.det(rest)) > 0.5:
            offsets[list(children)] = offsets[list(children)] @ rest @ tpose_frame.T
    return offsets


def rest_points(offsets: np.ndarray, joint: int) -> np.ndarray:
    """Points ``(16, 3)`` with ``joint`` at the origin and its children at their offsets (others 0)."""
    pts = np.zeros_like(offsets)
    for c in TORSO[joint]:
        pts[c] = offsets[c]
    return pts


def end_offsets(offsets: np.ndarray, end_length: float = 0.1, foot_length: float = 0.15) -> np.ndarray:
    """End Site offsets ``(16, 3)`` metres: ``end_length`` along the rest direction of each leaf bone
    (head up, wrists sideways), ``foot_length`` forward (+z) for the ankles; zero for other joints."""
    out = np.zeros((N_JOINTS, 3))
    for j in LEAVES:
        out[j] = end_length * TPOSE_DIRECTIONS[j]
    for j in FEET:
        out[j] = (0.0, 0.0, foot_length)
    return out
