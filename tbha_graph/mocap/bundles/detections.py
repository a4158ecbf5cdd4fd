"""The ``detections`` port: the bundle every segmenter outputs and every tracker reads, and reading it.

Keys (``n`` frames, ``C`` colour classes = the colour model's classes in order, patch colours then
``"head"``, ``K`` candidate slots per class):

* ``centres`` (n, C, K, 2) float32: candidate centres (x, y), pixels from the top-left; NaN in empty slots.
* ``areas`` (n, C, K) float32: candidate region areas, pixels²; 0 in empty slots.
* ``boxes`` (n, C, K, 4) float32: bounding rectangles (x0, y0, x1, y1), pixels; NaN in empty slots.
* ``colour_names`` (C,) str: class names (``colour_names[c]`` is the colour of ``centres[:, c]``).
* ``frame_index`` (n,) int64: video frame index of each row.
* ``fps`` () float, ``width`` () int, ``height`` () int: of the video the detections came from.

Within a class, filled slots come first, ordered by decreasing area. Same-coloured patches are not
identified here: that is the tracker's job.
"""
from __future__ import annotations

import numpy as np

from ...core.errors import NodeError
from ...core.types import Array

#: the declared keys (the port itself is :data:`tbha_graph.mocap.ports.DETECTIONS`)
DETECTION_KEYS = {
    "centres": Array("float", ("n_frames", "n_colours", "max_k", 2)),
    "areas": Array("float", ("n_frames", "n_colours", "max_k")),
    "boxes": Array("float", ("n_frames", "n_colours", "max_k", 4)),
    "colour_names": Array("str", ("n_colours",)),
    "frame_index": Array("int", ("n_frames",)),
    "fps": Array("float", ()),
    "width": Array("int", ()),
    "height": Array("int", ()),
}


class DetectionBuffer:
    """Fixed-size arrays for ``n_frames`` x ``n_classes`` x ``max_k`` candidates, filled frame by frame."""

    def __init__(self, n_frames: int, n_classes: int, max_k: int):
        self.max_k = int(max_k)
        self.centres = np.full((n_frames, n_classes, max_k, 2), np.nan, dtype=np.float32)
        self.areas = np.zeros((n_frames, n_classes, max_k), dtype=np.float32)
        self.boxes = np.full((n_frames, n_classes, max_k, 4), np.nan, dtype=np.float32)
        self.frame_index = np.zeros(n_frames, dtype=np.int64)

    def put(self, row: int, cls: int, centres: np.ndarray, areas: np.ndarray, boxes: np.ndarray) -> None:
        """Store candidates ``centres`` (k, 2), ``areas`` (k,), ``boxes`` (k, 4) of class ``cls`` in frame
        row ``row``: the ``max_k`` largest, by decreasing area."""
        areas = np.asarray(areas, dtype=np.float32).reshape(-1)
        if areas.size == 0:
            return
        order = np.argsort(-areas, kind="stable")[: self.max_k]
        k = order.size
        self.centres[row, cls, :k] = np.asarray(centres, dtype=np.float32).reshape(-1, 2)[order]
        self.areas[row, cls, :k] = areas[order]
        self.boxes[row, cls, :k] = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)[order]

    def to_arrays(self, names: list[str], fps: float, width: int, height: int) -> dict[str, np.ndarray]:
        return {
            "centres": self.centres,
            "areas": self.areas,
            "boxes": self.boxes,
            "colour_names": np.asarray(names, dtype=str),
            "frame_index": self.frame_index,
            "fps": np.asarray(float(fps)),
            "width": np.asarray(int(width)),
            "height": np.asarray(int(height)),
        }


def check_detections(det: dict) -> tuple[np.ndarray, np.ndarray]:
    """``centres`` (n, C, K, 2) and ``areas`` (n, C, K) of a detections bundle, as float64."""
    for key in ("centres", "areas", "colour_names", "fps", "width", "height"):
        if key not in det:
            raise NodeError(f"the detections bundle has no {key!r} array", hint="connect the output of a segment.* node")
    centres = np.asarray(det["centres"], dtype=np.float64)
    if centres.ndim != 4 or centres.shape[-1] != 2 or len(centres) == 0:
        raise NodeError(f"detections 'centres' must have shape (n_frames >= 1, n_colours, max_k, 2), got {centres.shape}")
    return centres, np.asarray(det["areas"], dtype=np.float64)
