"""Forward kinematics (BVH semantics) and the two-bone inverse kinematics of a leg, vectorised over frames.

Quaternions are scipy-ordered ``(x, y, z, w)`` ``(..., 4)`` float64; their arithmetic is
:mod:`tbha_graph.mocap.quat` (the project's one quaternion module).
"""
from __future__ import annotations

import numpy as np

from .quat import quat_apply, quat_mul


def validate_parents(parents: np.ndarray) -> np.ndarray:
    """Check a parent array ``(J,)``: root at index 0 with parent -1, every parent index < child index.

    Returns the array as int64; raises ``ValueError`` naming the first offending joint index.
    """
    parents = np.asarray(parents, dtype=np.int64)
    if parents.ndim != 1 or parents.size == 0:
        raise ValueError(f"parents must be a non-empty 1-D array, got shape {parents.shape}")
    if parents[0] != -1:
        raise ValueError(f"joint 0 must be the root (parent -1), got parent {parents[0]}")
    idx = np.arange(parents.size)
    bad = np.flatnonzero((parents[1:] < 0) | (parents[1:] >= idx[1:])) + 1
    if bad.size:
        j = int(bad[0])
        raise ValueError(
            f"joint {j} has parent {int(parents[j])}: parents must come before their children "
            "and only joint 0 may be a root"
        )
    return parents


def forward_kinematics(
    parents: np.ndarray,
    offsets: np.ndarray,
    local_quat: np.ndarray,
    root_position: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """World joint positions and rotations from local rotations (BVH semantics).

    Args:
        parents: ``(J,)`` int, parent index per joint, ``-1`` for the root (joint 0); parents
            come before children.
        offsets: ``(J, 3)`` rest offset of each joint from its parent, in the parent's frame
            (any length unit; the root's offset is ignored: ``root_position`` is absolute).
            Also accepted as ``(n, J, 3)`` for per-frame offsets (BVH joints with position channels).
        local_quat: ``(n, J, 4)`` xyzw rotation of each joint relative to its parent.
        root_position: ``(n, 3)`` root position, same unit as ``offsets``.

    Returns:
        ``positions`` ``(n, J, 3)`` (unit of ``offsets``) and ``world_quat`` ``(n, J, 4)`` xyzw, where
        ``world[j] = world[parent] * local[j]`` and ``pos[j] = pos[parent] + world[parent] (offsets[j])``;
        for the root ``pos = root_position`` and ``world = local[0]``.
    """
    parents = validate_parents(parents)
    local_quat = np.asarray(local_quat, dtype=np.float64)
    offsets = np.asarray(offsets, dtype=np.float64)
    root_position = np.asarray(root_position, dtype=np.float64)
    n, n_joints = local_quat.shape[0], parents.size
    if local_quat.shape != (n, n_joints, 4):
        raise ValueError(f"local_quat must have shape (n, {n_joints}, 4), got {local_quat.shape}")
    if offsets.shape not in ((n_joints, 3), (n, n_joints, 3)):
        raise ValueError(f"offsets must have shape ({n_joints}, 3) or ({n}, {n_joints}, 3), got {offsets.shape}")
    if root_position.shape != (n, 3):
        raise ValueError(f"root_position must have shape ({n}, 3), got {root_position.shape}")
    per_frame = offsets.ndim == 3

    positions = np.empty((n, n_joints, 3))
    world = np.empty((n, n_joints, 4))
    world[:, 0] = local_quat[:, 0]
    positions[:, 0] = root_position
    for j in range(1, n_joints):
        p = parents[j]
        off = offsets[:, j] if per_frame else offsets[j]
        world[:, j] = quat_mul(world[:, p], local_quat[:, j])
        positions[:, j] = positions[:, p] + quat_apply(world[:, p], off)
    return positions, world


def unit_rows(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` ``(..., 3)`` scaled to unit length; rows shorter than 1e-12 are left as they are."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def two_bone_ik(
    hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, target: np.ndarray, forward: np.ndarray,
    lengths: tuple | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Move knee and ankle so the ankle reaches ``target``, keeping both bone lengths; all (m, 3), any length unit.
    ``lengths``: ``(thigh, shin)`` (scalars or (m,)) to keep instead of the chain's own ``|knee - hip|``,
    ``|ankle - knee|`` (when ``hip`` is not where the chain hung from).

    The knee is placed in the plane through ``hip``, the new ankle and the original ``knee`` (its
    original bend plane). Where the original leg is nearly straight (the knee within 5 % of the thigh
    length of the hip-target line) that direction is blended towards ``forward`` (unit, (m, 3)), so
    the knee bends forward. Targets out of reach (farther than thigh + shin, or closer than their
    difference) are clamped along the hip-target line. Returns ``(knee, ankle, clamped)`` with
    ``clamped`` (m,) bool.
    """
    if lengths is None:
        l1, l2 = np.linalg.norm(knee - hip, axis=-1), np.linalg.norm(ankle - knee, axis=-1)
    else:
        l1, l2 = (np.broadcast_to(np.asarray(v, dtype=np.float64), hip.shape[:1]) for v in lengths)
    d = target - hip
    dist = np.linalg.norm(d, axis=-1)
    lo, hi = np.abs(l1 - l2) + 1e-9, l1 + l2
    clamped = (dist < lo) | (dist > hi)
    reach = np.clip(dist, lo, hi)
    u = np.where((dist > 1e-12)[:, None], d / np.where(dist > 1e-12, dist, 1.0)[:, None], unit_rows(ankle - hip))
    a = (l1**2 - l2**2 + reach**2) / (2.0 * reach)
    h = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    pole = (knee - hip) - np.einsum("mi,mi->m", knee - hip, u)[:, None] * u
    fwd = forward - np.einsum("mi,mi->m", forward, u)[:, None] * u
    alpha = np.clip(np.linalg.norm(pole, axis=-1) / (0.05 * l1), 0.0, 1.0)[:, None]
    side = unit_rows(alpha * unit_rows(pole) + (1.0 - alpha) * unit_rows(fwd))
    new_knee = hip + a[:, None] * u + h[:, None] * side
    return new_knee, hip + reach[:, None] * u, clamped
