"""The ``motion`` port (MOTION): 3D joint positions over time, and reading them.

Keys: ``joints`` (n_frames, 16, 3) float metres, world frame y up; ``fps`` () Hz; optional ``tracked``
(n_frames, 16) bool (False = missing/inferred), ``inferred`` (n_frames, 16) bool, ``joint_names`` (16,)
str. :func:`motion_joints` checks a bundle; :func:`with_joints` replaces its positions.
"""
from __future__ import annotations

import numpy as np

from ...core.errors import NodeError
from ..skeleton import JOINT_NAMES


def motion_joints(motion: dict, what: str = "motion") -> tuple[np.ndarray, float]:
    """The ``joints`` ``(n_frames, 16, 3)`` float64 metres and ``fps`` of a MOTION bundle, checked.

    Raises :class:`NodeError` for an empty clip, a non-positive or non-finite ``fps``, or a
    non-finite coordinate (naming the first frame and joint).
    """
    joints = np.asarray(motion["joints"], dtype=np.float64)
    fps = float(np.asarray(motion["fps"]))
    if joints.shape[0] == 0:
        raise NodeError(f"{what}: the clip has no frames", hint="check the upstream node's frame range")
    if not np.isfinite(fps) or fps <= 0:
        raise NodeError(f"{what}: fps is {fps}, expected a positive number of frames per second")
    bad = ~np.isfinite(joints).all(axis=-1)
    if bad.any():
        f, j = (int(i) for i in np.argwhere(bad)[0])
        raise NodeError(
            f"{what}: joint {JOINT_NAMES[j]!r} at frame {f} is not finite (NaN or inf); "
            f"{int(bad.sum())} joint positions are affected",
            hint="fill gaps upstream (a tracker's prediction or an interpolation node) before this node",
        )
    return joints, fps


def with_joints(motion: dict, joints: np.ndarray) -> dict:
    """A copy of the MOTION bundle with ``joints`` replaced (``tracked``, ``joint_names``... kept)."""
    out = dict(motion)
    out["joints"] = np.ascontiguousarray(joints, dtype=np.float64)
    return out
