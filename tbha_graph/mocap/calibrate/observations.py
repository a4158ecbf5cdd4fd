"""The T-pose at the start of a take: averaging the first frames of the 2D tracks, and the world
positions of the joints in the calibration world frame (see :func:`model_points`). The tracks are read
with :func:`tbha_graph.mocap.bundles.tracks.read_tracks`."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ...core.errors import NodeError, did_you_mean
from ..body import body_lengths, tpose_on_floor
from ..bundles.tracks import Tracks
from ..skeleton import CALIBRATION_JOINTS, JOINT_INDEX, JOINT_NAMES


def tpose_observation(tr: Tracks, joints: Sequence[str], n_frames: int, where: str = "tracks") -> tuple[np.ndarray, np.ndarray]:
    """Mean 2D position ``(len(joints), 2)`` px of ``joints`` over the first ``n_frames`` frames in which all
    of them are tracked (the T-pose at the start of the take); also returns the frame indices used."""
    idx = [JOINT_INDEX[j] for j in joints]
    ok = np.flatnonzero(tr.tracked[:, idx].all(axis=1))
    if ok.size == 0:
        raise NodeError(
            f"{where}: no frame has all of {list(joints)} tracked, so the T-pose cannot be measured",
            hint="the take must start with the actor in a T-pose facing the camera, torso patches visible",
        )
    used = ok[:n_frames]
    return tr.points[used][:, idx].mean(axis=0), used


def check_joint_names(names: list[str]) -> list[str]:
    """Pydantic field validator: every name is a joint (did-you-mean otherwise), none repeated."""
    for name in names:
        if name not in JOINT_INDEX:
            raise ValueError(f"unknown joint {name!r}{did_you_mean(name, JOINT_NAMES)}; joints are {', '.join(JOINT_NAMES)}")
    if len(set(names)) != len(names):
        raise ValueError("a joint is listed more than once")
    return names


def model_points(body: dict | None, ankle_height: float, joints: Sequence[str] = CALIBRATION_JOINTS, where: str = "body") -> np.ndarray:
    """World positions ``(len(joints), 3)`` metres of ``joints`` in the rest T-pose, all on the plane z = 0.

    Calibration world frame (:func:`tbha_graph.mocap.body.tpose_on_floor`): metres, y up,
    x = actor's left, actor faces +z, origin on the floor below the hips joint.
    """
    rest = tpose_on_floor(body_lengths(body, where), ankle_height)
    return rest[[JOINT_INDEX[j] for j in joints]]
