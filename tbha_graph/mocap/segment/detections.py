"""The ``detections`` bundle every segmenter outputs and every tracker reads.

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

from ...core.types import Array, Arrays

DETECTIONS = Arrays(
    {
        "centres": Array("float", ("n_frames", "n_colours", "max_k", 2)),
        "areas": Array("float", ("n_frames", "n_colours", "max_k")),
        "boxes": Array("float", ("n_frames", "n_colours", "max_k", 4)),
        "colour_names": Array("str", ("n_colours",)),
        "frame_index": Array("int", ("n_frames",)),
        "fps": Array("float", ()),
        "width": Array("int", ()),
        "height": Array("int", ()),
    },
    doc="per-frame candidate patch regions per colour class",
)


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
