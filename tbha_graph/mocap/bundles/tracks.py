"""The ``tracks`` port (TRACKS2D): 2D joint tracks, and reading them.

Keys: ``points`` (n_frames, 16, 2) float pixels (top-left origin); ``tracked`` (n_frames, 16) bool (False:
occluded/lost, ``points`` then holds the tracker's estimate); ``fps`` () Hz; ``width``, ``height`` () int
pixels; optional ``confidence`` (n_frames, 16), ``frame_index`` (n_frames,) and ``doubtful`` (n_frames,)
uint8 (:data:`tbha_graph.mocap.track.common.DOUBT` bits); a detector's may carry ``point_offsets`` (16, 2) metres
(each keypoint's offset from its joint centre) and ``facing`` (n_frames, 2, 3) (the thorax's and the pelvis's
fronts, unit, camera axes, zero where unknown), both read by ``reconstruct.solve_take``. :func:`read_tracks` checks a bundle and returns
it typed (:class:`Tracks`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.errors import NodeError
from ..skeleton import JOINT_INDEX, N_JOINTS


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


def body_boxes(points: np.ndarray, tracked: np.ndarray, margin: float) -> np.ndarray:
    """Per frame where the whole actor may be ``(n, 4)`` ``[x0, y0, x1, y1]`` full-resolution px, from the
    *tracked* points ``(n, 16, 2)`` only (a lost point the tracker holds may be stale): their box, made at least
    the body's height tall downwards from its top (the body's height in px: the median height of the frames
    with 12 or more tracked points), grown by ``margin`` times that height on every side. NaN rows: nothing
    tracked (the actor may be anywhere)."""
    ok = tracked & np.isfinite(points).all(axis=-1)
    x = np.where(ok, points[..., 0], np.nan)
    y = np.where(ok, points[..., 1], np.nan)
    # fmin / fmax skip NaN like nanmin / nanmax (which call them) without the all-NaN row's warning
    box = np.stack([np.fmin.reduce(x, 1), np.fmin.reduce(y, 1), np.fmax.reduce(x, 1), np.fmax.reduce(y, 1)], axis=1)
    full = ok.sum(axis=1) >= 12
    height = float(np.median(box[full, 3] - box[full, 1])) if full.any() else float(np.nanmax(box[:, 3] - box[:, 1], initial=100.0))
    box[:, 3] = np.maximum(box[:, 3], box[:, 1] + height)
    g = margin * height
    return box + np.array([-g, -g, g, g])
