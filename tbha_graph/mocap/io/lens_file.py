"""A lens calibration file (``lens.json``, written by ``pipelines/checkerboard.yaml``; or a Gyroflow lens profile or a
ROS camera_info file) applied to a video's frames.

A wide-angle or action camera bends straight lines; every stage after decoding assumes an ideal pinhole camera.
:func:`read_lens_file` turns the file into a :class:`~..ports.LensUndistortion` for the clip's frame size, and
:func:`undistort` remaps a frame to the pinhole camera it describes (its focal length the mean of the calibrated
``fx`` and ``fy``, square pixels, the principal point at the image centre ``((w - 1) / 2, (h - 1) / 2)``). Pixels
from the top-left; frames BGR ``uint8`` ``(h, w, 3)``.

Two of OpenCV's lens models (lens.json's ``model``; files without it are ``pinhole``): ``pinhole``, the radial and
tangential terms k1 k2 p1 p2 k3 of ``cv2.undistort``, for ordinary and wide-angle lenses; ``fisheye``, k1..k4 of the
angle off the axis (``cv2.fisheye``), for an action camera's widest modes. :func:`ideal_points` and
:func:`straighten_image` are the one place that tells them apart.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from ...core.errors import NodeError
from ...core.yamlfile import read_data_file
from ..camera import centred_intrinsics
from ..ports import LensUndistortion

_HINT = "give the lens.json that pipelines/checkerboard.yaml wrote for this camera at the video's resolution and zoom"


#: a ROS camera_info's ``distortion_model`` -> the lens model here
ROS_MODELS = {"plumb_bob": "pinhole", "equidistant": "fisheye"}

#: lens.json's ``model`` -> (number of distortion terms, their names)
LENS_MODELS = {"pinhole": (5, "k1 k2 p1 p2 k3"), "fisheye": (4, "k1 k2 k3 k4")}


def read_lens_file(path: str | Path, width: int, height: int, scaled: tuple[int, int] | None = None,
                   view: str = "calibrated") -> LensUndistortion:
    """The calibration in ``path`` for a video whose file frames are ``width`` x ``height`` pixels, read downscaled
    to ``scaled`` ``(w, h)`` pixels if given (the intrinsics scaled with the frames, pixel centres kept). ``view``:
    the straightened frames' focal length is the calibrated one (``calibrated``), or the one that keeps the filmed
    frame's left and right edges at mid-height in view (``width``).

    Three kinds of file are read (:func:`lens_fields`): the ``lens.json`` of ``pipelines/checkerboard.yaml``; a
    Gyroflow lens profile (JSON with ``calib_dimension`` and ``fisheye_params``: Gyroflow's database holds profiles
    of many action cameras' modes; one calibrated at another resolution of the same shape is scaled to the video's,
    as Gyroflow does); a ROS ``camera_info`` YAML (``image_width``, ``camera_matrix``, ``distortion_model``
    plumb_bob or equidistant). Raises :class:`NodeError` naming the file when it is none of these or was calibrated
    at another frame size."""
    path = Path(path)
    data = read_data_file(path, "lens file", NodeError)  # JSON, or YAML read safely; errors name the file and line
    fields = lens_fields(data, path)
    fx, fy, cx, cy, dist, model = (fields[k] for k in ("fx", "fy", "cx", "cy", "dist", "model"))
    w0, h0 = fields["width"], fields["height"]
    terms = LENS_MODELS[model]
    if len(dist) > terms[0] or any(dist[terms[0]:]) or not all(np.isfinite([fx, fy, cx, cy, *dist])) or min(fx, fy) <= 0:
        raise NodeError(f"lens file {path}: a {model} lens expects positive focal lengths and at most {terms[0]} finite "
                        f"distortion terms ({terms[1]}), has fx {fx}, fy {fy}, dist {dist}", hint=_HINT)
    if (w0, h0) != (width, height):
        if not fields["scalable"] or abs(w0 * height - h0 * width) > 0.005 * w0 * height:
            raise NodeError(f"lens file {path}: calibrated on {w0}x{h0} frames, the video's are {width}x{height}",
                            hint="film the checkerboard with the same camera, resolution and zoom as the take, and "
                                 "calibrate again" + ("" if not fields["scalable"] else
                                                      " (or take the Gyroflow profile of this resolution's shape)"))
    # to the frames as read: a profile of the same frame shape at another resolution, and decode's downscaling
    sx, sy = (scaled[0] / w0, scaled[1] / h0) if scaled is not None else (width / w0, height / h0)
    K = [[fx * sx, 0.0, (cx + 0.5) * sx - 0.5], [0.0, fy * sy, (cy + 0.5) * sy - 0.5], [0.0, 0.0, 1.0]]
    dist = (dist + [0.0] * terms[0])[:terms[0]]
    focal = 0.5 * (fx * sx + fy * sy)
    if view == "width":
        w, h = scaled if scaled is not None else (width, height)
        sides = ideal_points(np.array([[0.0, (h - 1) / 2.0], [w - 1.0, (h - 1) / 2.0]]), np.array(K), np.array(dist),
                             model, np.eye(3))  # normalised image coordinates of the filmed frame's sides
        reach = np.abs(sides[:, 0]).max()
        if not np.isfinite(reach) or reach <= 0:
            raise NodeError(f"lens file {path}: the frame's sides are 90 degrees or more off the axis; no pinhole "
                            "frame holds its whole width", hint="use decode.lens_view=calibrated")
        focal = min(focal, (w - 1) / 2.0 / float(reach))
    return LensUndistortion(K=K, model=model, dist=dist, focal_px=focal, source=str(path))


def lens_fields(data, path: Path) -> dict:
    """``{fx, fy, cx, cy (px), dist (list), model, width, height (px), scalable}`` from a lens file's content
    (:func:`read_lens_file`'s three kinds); ``scalable``: the file may serve another resolution of the same shape."""
    if not isinstance(data, dict):
        raise NodeError(f"lens file {path}: not a mapping of keys to values", hint=_HINT)
    try:
        if "calib_dimension" in data:  # a Gyroflow lens profile
            fisheye = data.get("fisheye_params")
            other = data.get("distortion_model")
            if not isinstance(fisheye, dict) or (other not in (None, "opencv_fisheye")) or data.get("use_opencv_standard"):
                raise NodeError(f"lens file {path}: a Gyroflow profile whose lens model ({other or 'not OpenCV fisheye'}) "
                                "is not read here; only OpenCV fisheye profiles (fisheye_params) are", hint=_HINT)
            K = np.asarray(fisheye["camera_matrix"], float)
            return {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "model": "fisheye",
                    "dist": [float(v) for v in fisheye["distortion_coeffs"]], "width": int(data["calib_dimension"]["w"]),
                    "height": int(data["calib_dimension"]["h"]), "scalable": True}
        if "camera_matrix" in data and "image_width" in data:  # a ROS camera_info YAML
            K = np.asarray(data["camera_matrix"]["data"], float).reshape(3, 3)
            kind = data.get("distortion_model", "plumb_bob")
            if kind not in ROS_MODELS:
                raise NodeError(f"lens file {path}: distortion_model {kind!r} is not read here (only "
                                f"{', '.join(ROS_MODELS)})", hint=_HINT)
            return {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "model": ROS_MODELS[kind],
                    "dist": [float(v) for v in data["distortion_coefficients"]["data"]],
                    "width": int(data["image_width"]), "height": int(data["image_height"]), "scalable": False}
        need = ("fx_px", "fy_px", "cx_px", "cy_px", "dist", "width", "height")
        missing = [k for k in need if k not in data]
        if missing:
            raise NodeError(f"lens file {path}: no {', '.join(missing)} in it (not a lens.json of "
                            "pipelines/checkerboard.yaml, a Gyroflow lens profile or a ROS camera_info file, or a lens.json "
                            "written before it recorded the image size)", hint=_HINT)
        model = data.get("model", "pinhole")
        if model not in LENS_MODELS:
            raise NodeError(f"lens file {path}: model {model!r} is not one of {', '.join(LENS_MODELS)}", hint=_HINT)
        return {"fx": float(data["fx_px"]), "fy": float(data["fy_px"]), "cx": float(data["cx_px"]),
                "cy": float(data["cy_px"]), "model": model, "dist": [float(v) for v in data["dist"]],
                "width": int(data["width"]), "height": int(data["height"]), "scalable": False}
    except (TypeError, ValueError, KeyError, IndexError) as exc:
        raise NodeError(f"lens file {path}: a value is missing or not a number ({type(exc).__name__}: {exc})",
                        hint=_HINT) from exc


def ideal_points(points: np.ndarray, K: np.ndarray, dist: np.ndarray, model: str, P: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` filmed through the lens (``K`` ``(3, 3)``, ``dist``, ``model`` as in lens.json) -> where
    the pinhole camera ``P`` ``(3, 3)`` puts the same rays ``(n, 2)``. Rays 90 degrees or more off the axis (a
    fisheye's rim) have no pinhole image: NaN."""
    pts = np.asarray(points, np.float64).reshape(-1, 1, 2)
    K, dist, P = (np.asarray(a, np.float64) for a in (K, dist, P))
    if model == "fisheye":
        out = cv2.fisheye.undistortPoints(pts, K, dist, P=P).reshape(-1, 2)
        # cv2.fisheye folds rays past 90 degrees back in front: the distorted radius says which those are
        theta_d = np.linalg.norm(cv2.undistortPoints(pts, K, None).reshape(-1, 2), axis=-1)
        k = np.concatenate([dist.ravel(), np.zeros(4)])[:4]
        theta = np.linspace(0, np.pi / 2, 512)
        theta_d_rim = np.max(theta * (1 + k[0] * theta**2 + k[1] * theta**4 + k[2] * theta**6 + k[3] * theta**8))
        out[theta_d >= theta_d_rim] = np.nan
        return out
    return cv2.undistortPoints(pts, K, dist, P=P).reshape(-1, 2)


def view_kept(K: np.ndarray, dist: np.ndarray, model: str, width: int, height: int, focal_px: float) -> float:
    """The fraction (0-1) of the filmed ``width`` x ``height`` frame (through the lens ``K``, ``dist``, ``model``)
    that the straightened frames (:func:`..camera.centred_intrinsics` of ``focal_px``, as :func:`undistort` makes
    them) still show: the rest falls outside them."""
    P = centred_intrinsics(focal_px, width, height)
    step = max(1, width // 320)  # a pixel in step x step: the fraction to a fraction of a percent
    u, v = np.meshgrid(np.arange(0, width, step, dtype=np.float64), np.arange(0, height, step, dtype=np.float64))
    ideal = ideal_points(np.stack([u, v], -1).reshape(-1, 2), K, dist, model, P)  # every filmed pixel, straightened
    inside = (ideal[:, 0] >= -0.5) & (ideal[:, 0] <= width - 0.5) & (ideal[:, 1] >= -0.5) & (ideal[:, 1] <= height - 0.5)
    return float(inside.mean())


def straighten_image(image: np.ndarray, K: np.ndarray, dist: np.ndarray, model: str, P: np.ndarray) -> np.ndarray:
    """``image`` ``(h, w[, 3])`` filmed through the lens, as the pinhole camera ``P`` ``(3, 3)`` of the same size
    sees it (bilinear; pixels whose ray falls outside the filmed frame black)."""
    h, w = image.shape[:2]
    m1, m2 = _maps(tuple(map(tuple, np.asarray(K, float))), tuple(np.ravel(dist).astype(float)), model,
                   tuple(map(tuple, np.asarray(P, float))), w, h)
    return cv2.remap(image, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


@lru_cache(maxsize=4)
def _maps(K: tuple, dist: tuple, model: str, P: tuple, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    K, dist, P = np.array(K), np.array(dist), np.array(P)
    if model == "fisheye":
        return cv2.fisheye.initUndistortRectifyMap(K, dist, np.eye(3), P, (width, height), cv2.CV_16SC2)
    return cv2.initUndistortRectifyMap(K, dist, None, P, (width, height), cv2.CV_16SC2)


def undistort(frame: np.ndarray, lens: LensUndistortion) -> np.ndarray:
    """``frame`` ``(h, w, 3)`` as the ideal camera of ``lens.focal_px`` (:func:`..camera.centred_intrinsics`) sees it (bilinear; pixels whose ray
    falls outside the file's frame black). The remap tables are made once per lens and size."""
    h, w = frame.shape[:2]
    return straighten_image(frame, np.array(lens.K), np.array(lens.dist), lens.model, centred_intrinsics(lens.focal_px, w, h))
