"""The ``rotations`` port (ROTATIONS): joint rotations relative to their parents, and reading them.

Keys: ``local_quat`` (n_frames, 16, 4) float, scipy order (x, y, z, w), each joint's rotation relative
to its parent, identity in the rest T-pose; ``root_position`` (n_frames, 3) metres; ``offsets`` (16, 3)
metres, rest offset of each joint from its parent (root: 0); ``end_offsets`` (16, 3) metres, End Site
offset of leaf joints (zero elsewhere); ``fps`` () Hz. Semantics as in BVH:
``world_rot[j] = world_rot[parent] * local[j]``, ``pos[j] = pos[parent] + world_rot[parent] @ offsets[j]``.
"""
from __future__ import annotations

import numpy as np

from ...core.errors import NodeError
from ..skeleton import JOINT_NAMES


def checked_rotations(rot: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Validate and normalise a ROTATIONS bundle: ``(local_quat (n, 16, 4) unit, root_position (n, 3),
    offsets (16, 3), end_offsets (16, 3), fps)``; :class:`NodeError` naming the frame/joint otherwise."""
    local = np.asarray(rot["local_quat"], dtype=np.float64)
    root = np.asarray(rot["root_position"], dtype=np.float64)
    offsets = np.asarray(rot["offsets"], dtype=np.float64)
    ends = np.asarray(rot["end_offsets"], dtype=np.float64)
    fps = float(rot["fps"])
    n = local.shape[0]
    if n == 0:
        raise NodeError("the rotations have no frames: nothing to export")
    if root.shape != (n, 3):
        raise NodeError(f"root_position has shape {root.shape}, expected ({n}, 3) to match local_quat")
    if not (np.isfinite(fps) and fps > 0):
        raise NodeError(f"fps is {fps}, expected a positive number of frames per second")
    for name, arr in (("offsets", offsets), ("end_offsets", ends)):
        if not np.isfinite(arr).all():
            j = int(np.argwhere(~np.isfinite(arr))[0, 0])
            raise NodeError(f"{name} of joint '{JOINT_NAMES[j]}' is not finite")
    bad = ~np.isfinite(root).all(axis=1)
    if bad.any():
        raise NodeError(f"root_position is not finite on frame {int(np.flatnonzero(bad)[0])}",
                        hint="fill gaps (e.g. with a smoothing/interpolation node) before exporting")
    norm = np.linalg.norm(local, axis=-1)
    bad = ~np.isfinite(norm) | (norm < 1e-6)
    if bad.any():
        f, j = (int(x) for x in np.argwhere(bad)[0])
        raise NodeError(f"local_quat of joint '{JOINT_NAMES[j]}' on frame {f} is not a rotation ({local[f, j]})",
                        hint="fill gaps (e.g. with a smoothing/interpolation node) before exporting")
    return local / norm[..., None], root, offsets, ends, fps
