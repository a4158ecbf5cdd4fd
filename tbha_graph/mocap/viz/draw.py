"""Drawing one video frame's annotations with OpenCV: skeletons, joint dots, markers, legend, counter.

Pixels are ``(u, v)`` from the top-left corner with pixel centres at integers (as everywhere in the
package); points are drawn with sub-pixel precision (OpenCV's ``shift``). Non-finite points are
skipped. All functions draw in place on a BGR ``uint8`` image ``(height, width, 3)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..skeleton import BONES

SHIFT = 4  # sub-pixel bits for cv2 drawing
_ONE = 1 << SHIFT
_LIMIT = 1e5  # pixels: coordinates are clipped to +-this before the fixed-point conversion


@dataclass(frozen=True)
class Sizes:
    """Drawing sizes in pixels for a frame: dot radius, line thickness, font scale."""

    dot: int
    line: int
    font: float

    @classmethod
    def for_frame(cls, height: int, dot: int | None = None, line: int | None = None) -> "Sizes":
        """Sizes that read well on a ``height``-pixel frame (5 px dots and 2 px lines at 480 px)."""
        return cls(
            dot=int(dot) if dot else max(3, round(height / 96)),
            line=int(line) if line else max(1, round(height / 240)),
            font=max(0.35, height / 960),
        )


def _fixed(p: np.ndarray) -> np.ndarray:
    return np.rint(np.clip(p, -_LIMIT, _LIMIT) * _ONE).astype(np.int32)


def draw_bones(img: np.ndarray, points: np.ndarray, color, thickness: int) -> None:
    """Lines along :data:`~tbha_graph.mocap.skeleton.BONES` between ``points`` ``(16, 2)`` px (bones with a
    non-finite end are skipped)."""
    p = np.asarray(points, dtype=np.float64)
    ok = np.isfinite(p).all(-1)
    segs = [_fixed(p[[a, b]]) for a, b in BONES if ok[a] and ok[b]]
    if segs:
        cv2.polylines(img, segs, False, color, thickness, cv2.LINE_AA, SHIFT)


def draw_dots(img: np.ndarray, points: np.ndarray, filled: np.ndarray, color, radius: int, thickness: int) -> None:
    """A filled dot at each point ``(16, 2)`` px where ``filled`` ``(16,)`` is True, a hollow circle of
    the same radius elsewhere (e.g. a tracker's prediction for a lost joint)."""
    p = np.asarray(points, dtype=np.float64)
    ok = np.isfinite(p).all(-1)
    fixed = _fixed(np.where(ok[:, None], p, 0.0))
    for j in np.flatnonzero(ok):
        cv2.circle(img, (int(fixed[j, 0]), int(fixed[j, 1])), radius * _ONE, color,
                   -1 if filled[j] else thickness, cv2.LINE_AA, SHIFT)


def draw_markers(img: np.ndarray, points: np.ndarray, color, size: int, thickness: int) -> None:
    """A cross at each finite point ``(16, 2)`` px (whole-pixel precision: OpenCV markers have no shift)."""
    p = np.asarray(points, dtype=np.float64)
    for u, v in np.rint(np.clip(p[np.isfinite(p).all(-1)], -_LIMIT, _LIMIT)).astype(int):
        cv2.drawMarker(img, (int(u), int(v)), color, cv2.MARKER_CROSS, size, thickness, cv2.LINE_AA)


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float, color=(255, 255, 255)) -> None:
    """White text (on a band already shaded by :func:`_shade`)."""
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)


def _shade(img: np.ndarray, x0: int, y0: int, x1: int, y1: int, alpha: float = 0.55) -> None:
    h, w = img.shape[:2]
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
    if x1 > x0 and y1 > y0:
        img[y0:y1, x0:x1] = (img[y0:y1, x0:x1] * (1.0 - alpha)).astype(np.uint8)


def draw_legend(img: np.ndarray, entries: list[tuple[str, str, tuple[int, int, int]]], sizes: Sizes) -> None:
    """A shaded box in the top-left corner listing ``(glyph, label, colour)`` entries; glyph is
    ``"dot"``, ``"ring"``, ``"line"`` or ``"cross"``."""
    if not entries:
        return
    (_, text_h), base = cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, sizes.font, 1)
    row = int(text_h + base + 6)
    width = max(cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, sizes.font, 1)[0][0] for _, label, _ in entries)
    pad, glyph_w = 6, 3 * sizes.dot + 8
    _shade(img, 0, 0, pad * 3 + glyph_w + width, pad * 2 + row * len(entries))
    for i, (glyph, label, color) in enumerate(entries):
        cy = pad + row * i + row // 2
        cx = pad + glyph_w // 2
        if glyph == "dot":
            cv2.circle(img, (cx, cy), sizes.dot, color, -1, cv2.LINE_AA)
        elif glyph == "ring":
            cv2.circle(img, (cx, cy), sizes.dot, color, sizes.line, cv2.LINE_AA)
        elif glyph == "cross":
            cv2.drawMarker(img, (cx, cy), color, cv2.MARKER_CROSS, 2 * sizes.dot + 4, 1, cv2.LINE_AA)
        else:
            cv2.line(img, (pad, cy), (pad + glyph_w, cy), color, sizes.line, cv2.LINE_AA)
        _text(img, label, (pad * 2 + glyph_w, cy + text_h // 2), sizes.font)


def draw_counter(img: np.ndarray, text: str, sizes: Sizes) -> None:
    """``text`` (e.g. ``"frame 12/120  0.40 s"``) on a shaded band in the bottom-left corner."""
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, sizes.font, 1)
    h = img.shape[0]
    _shade(img, 0, h - th - base - 12, tw + 16, h)
    _text(img, text, (8, h - base - 6), sizes.font)


def draw_flag(img: np.ndarray, text: str, color, sizes: Sizes) -> None:
    """A ``color`` border round the frame and ``text`` on a shaded band in the top-right corner."""
    h, w = img.shape[:2]
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), color, max(2, sizes.line + 1))
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, sizes.font, 1)
    _shade(img, w - tw - 16, 0, w, th + base + 12)
    _text(img, text, (w - tw - 8, th + 6), sizes.font, color)
