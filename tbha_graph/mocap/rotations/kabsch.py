"""``rotations.kabsch``: joint rotations by least-squares alignment of rest to current child offsets.

The alternative to :mod:`.quaternion`: ``hips`` and ``chest`` take the rotation ``R`` minimising
``sum_c w_c |R a_c - b_c|^2`` over their three children (``a_c`` rest offset, ``b_c`` current offset,
metres), solved for all frames at once by the Kabsch method (batched 3x3 SVD, reflection removed).
With ``weights="subtree"`` (default) each child weighs as many joints as move with it (9 for the
chest, 3 per leg), so the sum is the squared position error the torso rotation causes downstream;
``"equal"`` weighs the three children alike. Single-child joints have a rank-one problem whose
smallest solution is the shortest arc, and they share the hinge refinement, leaves and output
conventions of :mod:`.common`.
With ``torso_fit`` (default) the Kabsch rotations are the start of the same least-squares fit as
:mod:`.quaternion`'s (:mod:`.torso_fit`), and both solvers end at the same optimum; they differ with it off.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from ...core.node import node
from ..bundles.motion import motion_joints
from ..ports import MOTION, ROTATIONS
from ..rigid import procrustes
from ..skeleton import CHILDREN
from .common import SolverParams, empty_world, pose_from_torso, rest_skeleton, rotations_bundle
from .rest import TORSO
from .torso_fit import fit_torso


class KabschParams(SolverParams):
    """Parameters of ``rotations.kabsch``."""

    weights: Literal["subtree", "equal"] = Field(
        "subtree", description="weight of each torso child: number of joints moving with it ('subtree') or 1 ('equal')"
    )


def _subtree_size(j: int) -> int:
    return 1 + sum(_subtree_size(c) for c in CHILDREN[j])


def kabsch(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` minimising ``sum_k w_k |R a_k - b_k|^2``; ``a`` ``(k, 3)`` or
    ``(n, k, 3)``, ``b`` ``(n, k, 3)``, ``w`` ``(k,)``. Always proper rotations (det +1)."""
    return procrustes(a, b, w, center=False)[1]


def kabsch_rotations(joints: np.ndarray, fps: float, params: KabschParams | None = None) -> dict[str, np.ndarray]:
    """The ROTATIONS bundle for positions ``joints`` ``(n, 16, 3)`` metres (finite) at ``fps``."""
    from scipy.spatial.transform import Rotation

    p = params or KabschParams()
    joints = np.asarray(joints, dtype=np.float64)
    _, offsets = rest_skeleton(joints, p)
    world = empty_world(joints.shape[0])
    for j, children in TORSO.items():
        c = list(children)
        w = np.array([float(_subtree_size(k)) if p.weights == "subtree" else 1.0 for k in c])
        r = kabsch(offsets[c], joints[:, c] - joints[:, j : j + 1], w)
        world[:, j] = Rotation.from_matrix(r).as_quat()
    if p.torso_fit:
        world, joints = fit_torso(world, joints, offsets, p)
    return rotations_bundle(pose_from_torso(world, joints, offsets, p), joints, offsets, fps, p)


@node("rotations.kabsch", version=3, inputs={"motion": MOTION}, outputs={"rotations": ROTATIONS}, params=KabschParams)
def kabsch_node(ctx, motion):
    """Joint rotations from 3D joint positions by least-squares (Kabsch) alignment of the torso, hinge limbs."""
    joints, fps = motion_joints(motion)
    return {"rotations": kabsch_rotations(joints, fps, ctx.params)}


