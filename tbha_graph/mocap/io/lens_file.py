"""A lens calibration file (``lens.json``, written by ``pipelines/checkerboard.yaml``) applied to a video's frames.

A wide-angle or action camera bends straight lines; every stage after decoding assumes an ideal pinhole camera.
:func:`read_lens_file` turns the file into a :class:`~..ports.LensUndistortion` for the clip's frame size, and
:func:`undistort` remaps a frame to the pinhole camera it describes (its focal length the mean of the calibrated
``fx`` and ``fy``, square pixels, the principal point at the image centre ``((w - 1) / 2, (h - 1) / 2)``). Pixels
from the top-left; frames BGR ``uint8`` ``(h, w, 3)``.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from ...core.errors import NodeError
from ..camera import centred_intrinsics
from ..ports import LensUndistortion

_HINT = "give the lens.json that pipelines/checkerboard.yaml wrote for this camera at the video's resolution and zoom"


def read_lens_file(path: str | Path, width: int, height: int, scaled: tuple[int, int] | None = None) -> LensUndistortion:
    """The calibration in ``path`` for a video whose file frames are ``width`` x ``height`` pixels, read downscaled
    to ``scaled`` ``(w, h)`` pixels if given (the intrinsics scaled with the frames, pixel centres kept). Raises
    :class:`NodeError` naming the file when it is not such a file or was calibrated at another frame size."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise NodeError(f"lens file {path}: cannot be read as JSON ({exc})", hint=_HINT) from exc
    need = ("fx_px", "fy_px", "cx_px", "cy_px", "dist", "width", "height")
    missing = [k for k in need if not isinstance(data, dict) or k not in data]
    if missing:
        raise NodeError(f"lens file {path}: no {', '.join(missing)} in it (not a lens.json of pipelines/checkerboard.yaml, "
                        "or one written before it recorded the image size)", hint=_HINT)
    try:
        fx, fy, cx, cy = (float(data[k]) for k in ("fx_px", "fy_px", "cx_px", "cy_px"))
        dist = [float(v) for v in data["dist"]]
        w0, h0 = int(data["width"]), int(data["height"])
    except (TypeError, ValueError) as exc:
        raise NodeError(f"lens file {path}: a value is not a number ({exc})", hint=_HINT) from exc
    if len(dist) > 5 or any(dist[5:]) or not all(np.isfinite([fx, fy, cx, cy, *dist])) or min(fx, fy) <= 0:
        raise NodeError(f"lens file {path}: expects positive focal lengths and at most 5 finite distortion terms "
                        f"(k1 k2 p1 p2 k3), has fx {fx}, fy {fy}, dist {dist}", hint=_HINT)
    if (w0, h0) != (width, height):
        raise NodeError(f"lens file {path}: calibrated on {w0}x{h0} frames, the video's are {width}x{height}",
                        hint="film the checkerboard with the same camera, resolution and zoom as the take, and calibrate again")
    sx, sy = (scaled[0] / width, scaled[1] / height) if scaled is not None else (1.0, 1.0)
    K = [[fx * sx, 0.0, (cx + 0.5) * sx - 0.5], [0.0, fy * sy, (cy + 0.5) * sy - 0.5], [0.0, 0.0, 1.0]]
    return LensUndistortion(K=K, dist=(dist + [0.0] * 5)[:5], focal_px=0.5 * (fx * sx + fy * sy), source=str(path))


@lru_cache(maxsize=4)
def _maps(K: tuple, dist: tuple, focal: float, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    return cv2.initUndistortRectifyMap(np.array(K), np.array(dist), None, centred_intrinsics(focal, width, height),
                                       (width, height), cv2.CV_16SC2)


def undistort(frame: np.ndarray, lens: LensUndistortion) -> np.ndarray:
    """``frame`` ``(h, w, 3)`` as the ideal camera of ``lens.focal_px`` (:func:`..camera.centred_intrinsics`) sees it (bilinear; pixels whose ray
    falls outside the file's frame black). The remap tables are made once per lens and size."""
    h, w = frame.shape[:2]
    m1, m2 = _maps(tuple(map(tuple, lens.K)), tuple(lens.dist), float(lens.focal_px), w, h)
    return cv2.remap(frame, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
