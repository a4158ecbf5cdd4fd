"""Whole-image pixel classification by a colour model, and connected regions per class.

:class:`PixelClassifier` precomputes a 256 x 256 lookup table over the quantised chroma plane
(:func:`tbha_graph.mocap.color.spaces.index_planes`) giving, for every chroma bin, the patch colour whose
region (a wedge from its saturated reference towards the suit's white, see
:func:`tbha_graph.mocap.color.spaces.wedge_distance_sq`) holds it (the nearest one; none near the white), so classifying a frame is a few integer
OpenCV operations and one table lookup. Pixels darker than ``min_luma`` are never a patch colour; pixels
darker than ``dark_max_luma`` that are no patch colour are the head class.

Label images are ``uint8`` ``(h, w)``: 0 = no class, ``c + 1`` = class ``c`` of ``ColorModel.classes``.
Regions are traced with ``cv2.findContours`` (an order of magnitude faster here than
``cv2.connectedComponentsWithStats`` on a full frame) and taken as filled.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..bundles.colors import ColorModel
from ..color.spaces import index_chroma, index_planes, wedge_distance_sq


@dataclass(frozen=True)
class Regions:
    """Connected regions of one class: ``centres`` (k, 2) px, ``areas`` (k,) px², ``boxes`` (k, 4) x0, y0, x1, y1 px
    (inclusive pixel bounds), in the coordinates of the image they were found in."""

    centres: np.ndarray
    areas: np.ndarray
    boxes: np.ndarray

    def scaled(self, factor: float) -> "Regions":
        """Coordinates multiplied by ``factor`` (pixel centres map as ``(x + 0.5) * factor - 0.5``)."""
        f = float(factor)
        return Regions((self.centres + 0.5) * f - 0.5, self.areas * f * f, (self.boxes + 0.5) * f - 0.5)


class PixelClassifier:
    """Classify BGR pixels into the classes of a :class:`ColorModel` (see module docstring)."""

    #: :attr:`wedge_q` holds ``min(254, round(D2_SCALE * d²))`` of the normalised squared wedge distance
    D2_SCALE = 100.0

    def __init__(self, model: ColorModel):
        self.model = model
        self.space = model.space
        self.n_classes = len(model.classes)
        self.head_label = next((i + 1 for i, c in enumerate(model.classes) if c.kind == "dark"), 0)
        c1, c2 = index_chroma(self.space)  # chroma at lut[i1, i2]
        #: chroma (c1, c2) of every table entry, float32 (65536,) each
        self.c1, self.c2 = c1.astype(np.float32).reshape(-1), c2.astype(np.float32).reshape(-1)
        best = np.full(c1.shape, np.inf)
        lut = np.zeros(c1.shape, dtype=np.uint8)
        #: per class, the quantised normalised squared distance of every entry to the class's wedge
        #: (C, 65536) uint8; 255 = never (the dark class, chroma near the suit's white)
        self.wedge_q = np.full((self.n_classes, c1.size), 255, np.uint8)
        white = np.hypot(c1 - model.suit_ref[0], c2 - model.suit_ref[1]) < model.suit_tol
        ref, pale, tol = model.segments()
        for i, cls in enumerate(model.classes):
            if cls.kind != "chroma":
                continue
            d = wedge_distance_sq(c1, c2, model.suit_ref, ref[i], pale[i], tol[i])
            take = (d <= 1.0) & (d < best)
            lut[take] = i + 1
            best[take] = d[take]
            q = np.minimum(np.rint(d * self.D2_SCALE), 254).astype(np.uint8)
            q[white] = 255
            self.wedge_q[i] = q.reshape(-1)
        lut[white] = 0
        self.lut = lut.reshape(-1)

    def labels(self, bgr: np.ndarray) -> np.ndarray:
        """Label image ``(h, w)`` uint8 of a BGR uint8 frame ``(h, w, 3)``."""
        idx, luma3 = index_planes(self.space, bgr)
        lab = self.lut.take(idx)
        np.copyto(lab, 0, where=luma3 < 3.0 * self.model.min_luma)
        if self.head_label:
            np.copyto(lab, self.head_label, where=(luma3 < 3.0 * self.model.dark_max_luma) & (lab == 0))
        return lab


def class_mask(labels: np.ndarray, cls: int, close_px: int = 0) -> np.ndarray:
    """Mask (uint8 0/255) of class ``cls`` (0-based) in a label image; ``close_px`` > 0 fills holes and
    gaps smaller than that (a morphological closing by a square of that size)."""
    # numpy, not cv2.compare(labels, cls + 1): with a Python scalar OpenCV 5.0 refuses a 1x1 image and
    # OpenCV 5.1 returns a (4, 1) mask for it
    mask = np.equal(labels, cls + 1).astype(np.uint8)
    mask *= 255
    if close_px > 0:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((close_px, close_px), np.uint8))
    return mask


def mask_regions(mask: np.ndarray, min_area: float, convex: bool = False) -> Regions:
    """Regions of a mask (uint8, non-zero = in), each traced by its outer contour and taken as filled
    (holes such as specular highlights inside a patch count as inside); with ``convex`` each region is
    replaced by its convex hull (which also fills notches a highlight cuts into a patch's edge).
    Centres are the filled polygons' centroids; areas in pixels (polygon area plus half the perimeter,
    Pick's theorem); regions smaller than ``min_area`` px² are dropped."""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cents, areas, boxes = [], [], []
    for c in contours:
        x, y, w, h = cv2.boundingRect(c)
        if w * h < min_area:
            continue
        if convex:
            c = cv2.convexHull(c)
        mo = cv2.moments(c)
        area = mo["m00"] + 0.5 * cv2.arcLength(c, True) + 1.0
        if area < min_area:
            continue
        if mo["m00"] > 0:
            cents.append((mo["m10"] / mo["m00"], mo["m01"] / mo["m00"]))
        else:  # a line or a point: the mean of its contour points
            cents.append(tuple(c.reshape(-1, 2).mean(axis=0)))
        areas.append(area)
        boxes.append((x, y, x + w - 1, y + h - 1))
    if not areas:
        return Regions(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 4)))
    return Regions(np.array(cents, dtype=np.float64), np.array(areas, dtype=np.float64), np.array(boxes, dtype=np.float64))


def class_regions(labels: np.ndarray, cls: int, min_area: float, close_px: int = 0, convex: bool = False) -> Regions:
    """Connected regions of class ``cls`` (0-based) in a label image, area >= ``min_area`` px² (see
    :func:`class_mask` and :func:`mask_regions`)."""
    return mask_regions(class_mask(labels, cls, close_px), min_area, convex)
