"""Fast conversions of BGR ``uint8`` pixels to a 2D chroma plane plus a luma value.

Every space maps a pixel to ``(c1, c2, luma)``:

* ``"rg"`` (seed 000, eq. 1, the default): ``c1 = r = R / (R + G + B)``, ``c2 = g = G / (R + G + B)``,
  both in [0, 1]; luma ``(R + G + B) / 3`` in [0, 255]. Scaling a pixel's brightness leaves (r, g) unchanged.
* ``"hsv"``: saturation and hue as a point of the colour wheel, ``c1 = S cos(hue)``, ``c2 = S sin(hue)``,
  S in [0, 1] (so c1, c2 in [-1, 1] and hue needs no wrap-around); luma = V in [0, 255].
* ``"lab"``: CIE a*, b* (OpenCV's 8-bit scaling, centred on 0: about [-128, 127]); luma = L* scaled to [0, 255].

Input arrays may have any leading shape ``(..., 3)`` (a frame ``(h, w, 3)``, a stack of windows
``(m, s, s, 3)``, a list of pixels ``(n, 3)``); outputs are ``float32`` arrays of shape ``(...)``.
Costs on a 640x480 frame here: rg about 0.7 ms (channels split and one reciprocal, not a numpy
``sum(axis=2)``), hsv about 0.3 ms, lab about 1 ms.

:func:`quantise` maps (c1, c2) to ``uint8`` bins of a 256 x 256 lookup table (see
:mod:`tbha_graph.mocap.segment.labels`).
"""
from __future__ import annotations

from typing import Callable, Literal

import cv2
import numpy as np

Space = Literal["rg", "hsv", "lab"]
SPACES: tuple[str, ...] = ("rg", "hsv", "lab")

#: (low, high) of c1 and c2 in each space: the range mapped onto the 256 bins of :func:`quantise`.
CHROMA_RANGE: dict[str, tuple[float, float]] = {"rg": (0.0, 1.0), "hsv": (-1.0, 1.0), "lab": (-128.0, 128.0)}


def _as_image(bgr: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    """View ``(..., 3)`` uint8 as a 3-D image OpenCV accepts, and the leading shape to restore."""
    bgr = np.asarray(bgr)
    if bgr.dtype != np.uint8 or bgr.shape[-1:] != (3,):
        raise ValueError(f"expected BGR uint8 pixels of shape (..., 3), got {bgr.dtype} {bgr.shape}")
    lead = bgr.shape[:-1]
    if bgr.ndim == 3:
        return bgr, lead
    if bgr.ndim < 3:
        return bgr.reshape(1, -1, 3), lead
    return np.ascontiguousarray(bgr).reshape(-1, bgr.shape[-2], 3), lead


def rg_chromaticity(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rg chromaticity (seed eq. 1): ``r = R/(R+G+B)``, ``g = G/(R+G+B)`` in [0, 1], luma ``(R+G+B)/3``.

    Black pixels (R+G+B = 0) get r = g = 0. Shapes ``(..., 3) uint8 -> 3 x (...) float32``.
    """
    img, lead = _as_image(bgr)
    b, g, r = cv2.split(img)
    s = cv2.add(cv2.add(b, g, dtype=cv2.CV_32F), r, dtype=cv2.CV_32F)
    inv = 1.0 / np.maximum(s, 1.0)
    s *= np.float32(1.0 / 3.0)
    return (r * inv).reshape(lead), (g * inv).reshape(lead), s.reshape(lead)


_HUE = np.arange(256, dtype=np.float64) * (2.0 * np.pi / 180.0)  # OpenCV 8-bit hue: 0..179 = 0..358 degrees
_COS = (np.cos(_HUE) / 255.0).astype(np.float32)
_SIN = (np.sin(_HUE) / 255.0).astype(np.float32)


def hsv_chroma(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Colour-wheel coordinates ``(S cos H, S sin H)`` with S in [0, 1], and luma V in [0, 255]."""
    img, lead = _as_image(bgr)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    h, s, v = cv2.split(hsv)
    s32 = s.astype(np.float32)
    c1 = _COS[h] * s32
    c2 = _SIN[h] * s32
    return c1.reshape(lead), c2.reshape(lead), v.astype(np.float32).reshape(lead)


def lab_chroma(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CIE a*, b* centred on 0 (OpenCV 8-bit scaling) and luma L* scaled to [0, 255]."""
    img, lead = _as_image(bgr)
    lab = cv2.cvtColor(img, cv2.COLOR_BGR2Lab)
    l, a, b = cv2.split(lab)
    c1 = a.astype(np.float32) - np.float32(128.0)
    c2 = b.astype(np.float32) - np.float32(128.0)
    return c1.reshape(lead), c2.reshape(lead), l.astype(np.float32).reshape(lead)


CONVERTERS: dict[str, Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]] = {
    "rg": rg_chromaticity,
    "hsv": hsv_chroma,
    "lab": lab_chroma,
}


def convert(space: str, bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(c1, c2, luma)`` of BGR uint8 pixels ``(..., 3)`` in ``space`` (one of :data:`SPACES`)."""
    try:
        fn = CONVERTERS[space]
    except KeyError:
        raise ValueError(f"unknown colour space {space!r}; known: {', '.join(SPACES)}") from None
    return fn(bgr)


def rgb_to_chroma(space: str, rgb01: np.ndarray) -> np.ndarray:
    """Chroma ``(..., 2)`` of sRGB colours given as floats in [0, 1], shape ``(..., 3)`` in R, G, B order."""
    rgb01 = np.asarray(rgb01, dtype=np.float64)
    bgr = np.clip(np.rint(rgb01[..., ::-1] * 255.0), 0, 255).astype(np.uint8)
    c1, c2, _ = convert(space, bgr.reshape(-1, 3))
    return np.stack([c1, c2], axis=-1).astype(np.float64).reshape(rgb01.shape[:-1] + (2,))


def quantise(space: str, c1: np.ndarray, c2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map chroma coordinates to ``uint8`` bins 0..255 over :data:`CHROMA_RANGE` (saturating)."""
    lo, hi = CHROMA_RANGE[space]
    alpha = 255.0 / (hi - lo)
    beta = -lo * alpha + 0.5
    shape = np.shape(c1)
    flat = (-1, shape[-1]) if len(shape) >= 2 else (1, -1)
    # convertScaleAbs saturates to uint8; alpha * c + beta >= 0 over the range, so abs() is a no-op
    q1 = cv2.convertScaleAbs(np.asarray(c1).reshape(flat), alpha=alpha, beta=beta)
    q2 = cv2.convertScaleAbs(np.asarray(c2).reshape(flat), alpha=alpha, beta=beta)
    return q1.reshape(shape), q2.reshape(shape)


def bin_centres(space: str) -> np.ndarray:
    """Chroma value at the centre of each of the 256 bins of :func:`quantise`, shape (256,)."""
    lo, hi = CHROMA_RANGE[space]
    return lo + np.arange(256, dtype=np.float64) * (hi - lo) / 255.0
