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

:func:`index_planes` is the whole-frame fast path: two 8-bit chroma coordinates per pixel addressing
a 256 x 256 lookup table (see :mod:`tbha_graph.mocap.segment.labels`).
"""
from __future__ import annotations

from typing import Callable, Literal

import cv2
import numpy as np

Space = Literal["rg", "hsv", "lab"]
SPACES: tuple[str, ...] = ("rg", "hsv", "lab")



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


def index_planes(space: str, bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whole-frame fast path: ``(index, luma3)`` of a BGR uint8 frame ``(h, w, 3)``, both uint16 ``(h, w)``.

    ``index = i1 << 8 | i2`` addresses a 256 x 256 lookup table over two 8-bit chroma coordinates
    (:func:`index_chroma` gives the chroma of each entry); ``luma3`` is 3 x the space's luma (0..765).
    Integer arithmetic only (about 0.5 ms for rg on 640x480 here), no float temporaries, and no OpenCV
    array-with-Python-scalar operations (their shape rules for tiny arrays differ between OpenCV 5.0 and 5.1):

    * rg: ``i1 = round(255 R / (R+G+B))``, ``i2 = round(255 G / (R+G+B))``, ``luma3 = R+G+B``;
    * hsv: ``i1 = H`` (0..179), ``i2 = S``, ``luma3 = 3 V``;
    * lab: ``i1 = a``, ``i2 = b`` (OpenCV 8-bit, offset 128), ``luma3 = 3 L``.
    """
    if space == "rg":
        b, g, r = cv2.split(bgr)
        s = cv2.add(b, g, dtype=cv2.CV_16U)
        s = cv2.add(s, r.astype(np.uint16), dtype=cv2.CV_16U)
        i1 = cv2.divide(r.astype(np.uint16), s, scale=255.0)
        i2 = cv2.divide(g.astype(np.uint16), s, scale=255.0)
        luma3 = s
    elif space in ("hsv", "lab"):
        conv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV if space == "hsv" else cv2.COLOR_BGR2Lab)
        x, y, z = cv2.split(conv)
        if space == "hsv":
            i1, i2, luma = x.astype(np.uint16), y.astype(np.uint16), z
        else:
            i1, i2, luma = y.astype(np.uint16), z.astype(np.uint16), x
        # numpy, not cv2.multiply(luma, 3): OpenCV 5.1 takes a 1x1 array with a Python scalar for a 4-vector
        # (the result comes back (4, 1)), OpenCV 5.0 refuses it
        luma3 = luma.astype(np.uint16)
        luma3 *= 3
    else:
        raise ValueError(f"unknown colour space {space!r}; known: {', '.join(SPACES)}")
    i1 <<= 8
    return cv2.bitwise_or(i1, i2), luma3


def index_chroma(space: str) -> tuple[np.ndarray, np.ndarray]:
    """Chroma ``(c1, c2)``, each (256, 256) float64, at every entry ``[i1, i2]`` of :func:`index_planes`."""
    i1, i2 = np.meshgrid(np.arange(256.0), np.arange(256.0), indexing="ij")
    if space == "rg":
        return i1 / 255.0, i2 / 255.0
    if space == "hsv":
        h = i1 * (2.0 * np.pi / 180.0)
        return i2 / 255.0 * np.cos(h), i2 / 255.0 * np.sin(h)
    if space == "lab":
        return i1 - 128.0, i2 - 128.0
    raise ValueError(f"unknown colour space {space!r}; known: {', '.join(SPACES)}")


def wedge_distance_sq(c1, c2, white, ref, pale, tol):
    """Squared normalised distance (1 = on the border) from chroma points ``(c1, c2)`` to a colour's
    region: the wedge of chromaticities of that colour mixed with the suit's white.

    Mixing a colour with white (a specular sheen, a clipped channel, the blurred edge against the suit)
    moves its chromaticity along the ray from the white point ``white`` through the colour's reference
    ``ref``; the hue is the angle around ``white``. So the region is the part of that ray from the pale
    end ``pale`` to ``tol`` beyond ``ref``, widened by ``tol`` at ``ref`` and proportionally less towards
    the white point (colours' wedges stay apart as they converge on white). ``white`` is a pair of
    scalars; ``ref``, ``pale`` pairs and ``tol`` broadcast against ``c1``, ``c2`` (e.g. per-window (m, 1, 1)
    arrays against pixels (m, S, S))."""
    w1, w2 = white
    a1, a2 = ref[0] - w1, ref[1] - w2
    R = np.sqrt(a1 * a1 + a2 * a2)
    u1, u2 = a1 / R, a2 / R
    lo = np.sqrt((pale[0] - w1) ** 2 + (pale[1] - w2) ** 2)
    v1, v2 = c1 - w1, c2 - w2
    along = v1 * u1 + v2 * u2
    perp = v1 * u2 - v2 * u1
    width = tol * np.maximum(along, lo) / R
    below = np.maximum(lo - along, 0) / (tol * lo / R)
    beyond = np.maximum(along - R, 0) / tol
    return (perp / width) ** 2 + below * below + beyond * beyond
