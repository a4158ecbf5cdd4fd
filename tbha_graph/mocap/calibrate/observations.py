"""The T-pose at the start of a take: reading a ``TRACKS2D`` bundle, averaging the first frames, and the
world positions of the joints in the calibration world frame (see :func:`model_points`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...core.errors import NodeError, did_you_mean
from ..body import body_lengths, tpose_on_floor
from ..skeleton import CALIBRATION_JOINTS, JOINT_INDEX, JOINT_NAMES, N_JOINTS


@dataclass(frozen=True)
class Tracks:
    """A checked ``TRACKS2D`` bundle: ``points`` (n, 16, 2) px top-left origin, ``tracked`` (n, 16) bool,
    ``fps``, image ``width`` and ``height`` in pixels."""

    points: np.ndarray
    tracked: np.ndarray
    fps: float
    width: int
    height: int

    @property
    def n_frames(self) -> int:
        return int(self.points.shape[0])

    @property
    def centre(self) -> np.ndarray:
        """Image centre ``(2,)`` px, the principal point convention of :meth:`Camera.look_at`."""
        return np.array([(self.width - 1) / 2.0, (self.height - 1) / 2.0])


def read_tracks(tracks: dict, where: str = "tracks") -> Tracks:
    """Check a ``TRACKS2D`` bundle (keys, shapes, finite values, image size) and return it typed."""
    for key in ("points", "tracked", "width", "height"):
        if key not in tracks:
            raise NodeError(
                f"{where}: the 2D tracks have no {key!r} array (present: {sorted(tracks)})",
                hint="connect the output of a tracking node (TRACKS2D: points, tracked, fps, width, height)",
            )
    points = np.asarray(tracks["points"], dtype=np.float64)
    tracked = np.asarray(tracks["tracked"], dtype=bool)
    if points.ndim != 3 or points.shape[1:] != (N_JOINTS, 2) or tracked.shape != points.shape[:2]:
        raise NodeError(f"{where}: points {points.shape} / tracked {tracked.shape} are not (n, {N_JOINTS}, 2) / (n, {N_JOINTS})")
    if points.shape[0] == 0:
        raise NodeError(f"{where}: the tracks have no frames", hint="check the frame range of the video")
    bad = ~np.isfinite(points).all(axis=2)
    if bad.any():
        f, j = np.argwhere(bad)[0]
        raise NodeError(
            f"{where}: frame {f}, joint {list(JOINT_INDEX)[j]!r} has a non-finite 2D position",
            hint="the tracker must fill every point (a prediction where the joint is lost, tracked=False)",
        )
    width, height = int(np.asarray(tracks["width"])), int(np.asarray(tracks["height"]))
    if width <= 0 or height <= 0:
        raise NodeError(f"{where}: image size {width}x{height} px is not positive")
    fps = float(np.asarray(tracks.get("fps", 0.0)))
    return Tracks(points=points, tracked=tracked, fps=fps, width=width, height=height)


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
