"""16-joint ROTATIONS -> SMPL pose parameters ``(n, 72)`` axis-angle and root translation ``(n, 3)``.

Both rest poses are T-poses in the same axes (metres, y up, facing +z, left arm along +x), and both
rotation sets are "identity = rest pose", composed parent-first in world-aligned rest axes (BVH semantics:
``world[j] = world[parent] * local[j]``; SMPL: ``G_k = G_parent * R_k``). So each SMPL joint takes the world
rotation of the TBHA joint that rotates the same body segment (:data:`~.kintree.SMPL_FROM_TBHA`: the
pelvis takes the hips' rotation, SMPL's shoulder (upper arm) the TBHA shoulder's, and so on), and its pose
parameter is its rotation relative to its SMPL parent:

* the three spine joints split the chest's rotation relative to the hips: ``spine="even"`` gives each a
  third of the rotation vector (same axis, so together they make exactly the chest's rotation), ``"top"``
  puts it all on spine3;
* joints the 16-joint model cannot see stay at rest relative to their parent: the collars (so the
  shoulder's parent frame is the chest's), the hands, the feet (the foot follows the ankle rigidly);
* rest directions: with no model, SMPL's template is taken as the same T-pose (identity maps to identity).
  With the model's rest joints (``rest_joints``, (24, 3)), the upper arms, forearms, thighs and shins are
  re-aimed: ``W_smpl[k] = W_tbha[k] · C_k`` where ``C_k`` is the shortest arc taking SMPL's rest bone
  direction to the TBHA rest direction, so the posed SMPL bone points where the TBHA bone points
  (SMPL's arms in the template slope slightly; without this they would slope in every frame too).

Root translation (SMPL/AMASS convention): the posed pelvis joint is ``trans + J_0(β)``; with the model's rest
pelvis ``J_0`` the pelvis lands on the TBHA root position (``trans = root_position − J_0``); without a model
``J_0`` is taken as 0. ``up="z"`` re-expresses everything in a z-up world (x, y, z)_zup = (x, −z, y)_yup
(AMASS's raw files are z-up), turning the global orientation and translation accordingly.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from ..quat import quat_inv, quat_mul
from ..skeleton import JOINT_INDEX, N_JOINTS, PARENTS, TPOSE_DIRECTIONS
from .kintree import (
    LIMB_SEGMENTS, N_SMPL_JOINTS, SMPL_FROM_TBHA, SMPL_INDEX, SMPL_JOINT_NAMES, SMPL_PARENTS, SPINE_JOINTS,
)

#: world (x, y, z) y-up -> z-up: x stays, y (up) becomes z, z (forward) becomes -y.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def world_quaternions(local_quat: np.ndarray) -> np.ndarray:
    """World rotations ``(n, 16, 4)`` xyzw of the 16 joints from their local rotations (root first)."""
    lq = np.asarray(local_quat, dtype=np.float64)
    world = np.empty_like(lq)
    world[:, 0] = lq[:, 0]
    for j in range(1, N_JOINTS):
        world[:, j] = quat_mul(world[:, PARENTS[j]], lq[:, j])
    return world


def rest_corrections(rest_joints: np.ndarray | None) -> np.ndarray:
    """Per-SMPL-joint rest corrections ``C_k`` ``(24, 4)`` xyzw (identity unless listed in LIMB_SEGMENTS)."""
    from scipy.spatial.transform import Rotation

    C = np.tile([0.0, 0.0, 0.0, 1.0], (N_SMPL_JOINTS, 1))
    if rest_joints is None:
        return C
    J = np.asarray(rest_joints, dtype=np.float64).reshape(N_SMPL_JOINTS, 3)
    for k_name, (smpl_child, tbha_child) in LIMB_SEGMENTS.items():
        k = SMPL_INDEX[k_name]
        d_smpl = J[SMPL_INDEX[smpl_child]] - J[k]
        d_tbha = TPOSE_DIRECTIONS[JOINT_INDEX[tbha_child]]
        if np.linalg.norm(d_smpl) > 1e-9:
            C[k] = Rotation.align_vectors(d_tbha[None], d_smpl[None])[0].as_quat()
    return C


def smpl_pose_from_rotations(
    local_quat: np.ndarray,
    root_position: np.ndarray,
    *,
    rest_joints: np.ndarray | None = None,
    spine: Literal["even", "top"] = "even",
    up: Literal["y", "z"] = "y",
) -> tuple[np.ndarray, np.ndarray]:
    """SMPL ``poses`` ``(n, 72)`` axis-angle radians and ``trans`` ``(n, 3)`` metres (module docstring).

    ``local_quat`` ``(n, 16, 4)`` xyzw and ``root_position`` ``(n, 3)`` metres are a ROTATIONS bundle's;
    ``rest_joints`` ``(24, 3)`` the model's rest joints for the shape used (None: no model).
    """
    from scipy.spatial.transform import Rotation

    lq = np.asarray(local_quat, dtype=np.float64)
    n = lq.shape[0]
    if lq.shape != (n, N_JOINTS, 4):
        raise ValueError(f"local_quat must be (n, {N_JOINTS}, 4), got {lq.shape}")
    W = world_quaternions(lq)
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    Ws = np.tile(ident, (n, N_SMPL_JOINTS, 1))
    C = rest_corrections(rest_joints)

    # spine: split the chest's rotation relative to the hips over spine1..3
    chest_rel = Rotation.from_quat(lq[:, JOINT_INDEX["chest"]]).as_rotvec()
    share = {"even": (1 / 3, 1 / 3, 1 / 3), "top": (0.0, 0.0, 1.0)}[spine]
    local_spine = {name: Rotation.from_rotvec(chest_rel * s).as_quat() for name, s in zip(SPINE_JOINTS, share)}

    # walk the SMPL tree parent-first building world rotations
    at_rest = np.zeros(N_SMPL_JOINTS, dtype=bool)
    for k in range(N_SMPL_JOINTS):
        name = SMPL_JOINT_NAMES[k]
        parent = SMPL_PARENTS[k]
        if name in SMPL_FROM_TBHA:
            Ws[:, k] = quat_mul(W[:, JOINT_INDEX[SMPL_FROM_TBHA[name]]], C[k])
        elif name in local_spine:
            Ws[:, k] = quat_mul(Ws[:, parent], local_spine[name])
        else:
            Ws[:, k] = Ws[:, parent]
            at_rest[k] = True
    local = quat_mul(quat_inv(Ws[:, np.maximum(SMPL_PARENTS, 0)]), Ws)
    local[:, 0] = Ws[:, 0]
    local[:, at_rest] = ident  # exactly, not up to rounding

    J0 = np.zeros(3) if rest_joints is None else np.asarray(rest_joints, dtype=np.float64).reshape(N_SMPL_JOINTS, 3)[0]
    root = np.asarray(root_position, dtype=np.float64).reshape(n, 3)
    if up == "z":
        Rup = Rotation.from_matrix(Y_UP_TO_Z_UP)
        local[:, 0] = (Rup * Rotation.from_quat(local[:, 0])).as_quat()
        root = root @ Y_UP_TO_Z_UP.T
    trans = root - J0
    poses = Rotation.from_quat(local.reshape(-1, 4)).as_rotvec().reshape(n, N_SMPL_JOINTS * 3)
    return poses, trans
