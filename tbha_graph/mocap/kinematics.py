"""Forward kinematics and small quaternion helpers, vectorised over frames.

Quaternions are stored in scipy's scalar-last order ``(x, y, z, w)`` as float64 arrays of shape
``(..., 4)``; every function broadcasts over the leading axes. Rotations act on column vectors
(``q`` applied to ``v`` is ``R(q) @ v``) and ``quat_mul(a, b)`` is the rotation "first ``b``, then
``a``", i.e. ``R(a) @ R(b)``, matching ``scipy.spatial.transform.Rotation`` (``Ra * Rb``).

This module is self-contained (numpy only): plain numpy quaternion arithmetic is several times
faster than building scipy ``Rotation`` objects for small per-joint batches.
"""
from __future__ import annotations

import numpy as np


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` xyzw; broadcasts; returns ``(..., 4)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ),
        axis=-1,
    )


def quat_inv(q: np.ndarray) -> np.ndarray:
    """Inverse of quaternions ``(..., 4)`` xyzw (conjugate divided by the squared norm)."""
    q = np.asarray(q, dtype=np.float64)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return conj / np.sum(q * q, axis=-1, keepdims=True)


def quat_apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` ``(..., 3)`` by unit quaternions ``q`` ``(..., 4)`` xyzw; broadcasts.

    Uses ``v' = v + 2w (u x v) + 2 u x (u x v)`` with ``u`` the vector part (no matrices built).
    """
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` xyzw."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack(
        (
            1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
            2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
            2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
        ),
        axis=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` scaled to unit norm."""
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


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
