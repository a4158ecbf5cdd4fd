"""``calibrate.checkerboard``: lens intrinsics from a checkerboard clip, as a studio does once per lens.

Corners are found with ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` on every ``step``-th frame of a
video file (or every image of a folder, in name order); ``cv2.calibrateCamera`` then solves K and the
distortion. The output camera's extrinsics are those of the **first view with a detected board**: world
frame = that board, origin at its first inner corner, x along the rows of corners, y along the columns,
z into the board (OpenCV's object-point convention), metres. Feed K (and dist) to ``calibrate.pnp`` to place
the camera in the actor's world, or the report (``lens.json``) to ``io.video``'s ``lens``.

``distortion: fisheye`` solves OpenCV's fisheye model instead (``cv2.fisheye.calibrate``: k1..k4 of the angle off
the axis), for an action camera's widest modes, which the pinhole model's k1 k2 cannot follow; lens.json then says
``"model": "fisheye"``, and the output camera is the pinhole camera of the straightened frames (the file's focal
length, principal point at the centre, no distortion), as ``io.video`` reads them with the file.

The report holds how far the lens moves the image's corners (``bend_px_at_corners``: above a pixel or so a take needs
the whole lens file, not just its focal length), how much of the filmed frame the straightened frames keep
(``view_kept_pct``: a barrel or fisheye lens's straightened frame shows less at its edges; keep the actor inside it),
and ``picture`` shows the view whose board reaches farthest from the image's centre as filmed and with the lens
taken out: each row of corners against the straight line through its ends (:func:`draw_rows`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.atomic import atomic_write_bytes
from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..camera import Camera, centred_intrinsics
from ..io.lens_file import ideal_points, straighten_image, view_kept
from ..ports import CAMERA, IMAGE, REPORT

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: below this fraction of the way from the image's centre to its corners reached by a board, a bending lens's
#: calibration is an extrapolation at the frame's rim, and the run warns
BOARD_REACH_WARN = 0.85


class CheckerboardParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="video file, or a folder of images, showing the checkerboard in several poses")
    columns: int = Field(9, ge=2, description="inner corners per row of the board")
    rows: int = Field(6, ge=2, description="inner corners per column of the board")
    square_size: float = Field(0.025, gt=0, description="side of one square", json_schema_extra={"unit": "m"})
    step: int = Field(10, ge=1, description="use every step-th video frame")
    max_views: int = Field(40, ge=3, description="at most this many views with a detected board are used (evenly spread)")
    distortion: Literal["none", "k1k2", "full", "fisheye"] = Field(
        "k1k2", description="distortion solved: none, k1 k2, k1 k2 p1 p2 k3 (OpenCV's pinhole model), or fisheye "
        "(OpenCV's fisheye model, k1..k4: an action camera's widest modes)")


def iter_images(path: Path, step: int) -> Iterator[tuple[int, np.ndarray]]:
    """``(index, grey image (h, w) uint8)`` from a folder of images (name order) or every ``step``-th video frame."""
    import cv2

    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise NodeError(f"{path}: the folder holds no images ({', '.join(IMAGE_SUFFIXES)})")
        for i, f in enumerate(files):
            img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise NodeError(f"{f}: cannot read the image")
            yield i, img
        return
    if not path.is_file():
        raise NodeError(f"checkerboard clip {path} does not exist", hint="give a video file or a folder of images")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise NodeError(f"{path}: OpenCV cannot open the video", hint="convert it to mp4 (mp4v/H.264) or extract images to a folder")
    try:
        i = 0
        while True:
            ok = cap.grab()
            if not ok:
                break
            if i % step == 0:
                ok, frame = cap.retrieve()
                if ok:
                    yield i, cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            i += 1
    finally:
        cap.release()


def board_points(columns: int, rows: int, square: float) -> np.ndarray:
    """Object points ``(columns * rows, 3)`` metres in OpenCV's corner order (row by row), z = 0."""
    g = np.mgrid[0:columns, 0:rows].T.reshape(-1, 2)
    return np.concatenate([g * square, np.zeros((len(g), 1))], axis=1).astype(np.float32)


def find_corners(grey: np.ndarray, columns: int, rows: int) -> np.ndarray | None:
    """Sub-pixel inner corners ``(columns * rows, 1, 2)`` float32, or None when the board is not found."""
    import cv2

    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(grey, (columns, rows), flags=flags)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria)


def bend_at_corners(K: np.ndarray, dist: np.ndarray, width: int, height: int, model: str = "pinhole") -> float:
    """How far, pixels, the lens (``K`` ``(3, 3)``, OpenCV ``dist`` of ``model``) moves the image's four corners from
    where an ideal camera with the same ``K`` would put them (the largest of the four; inf when a corner's ray is 90
    degrees or more off the axis)."""
    corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], np.float64)
    moved = np.linalg.norm(ideal_points(corners, K, dist, model, K) - corners, axis=-1)
    return float(np.inf) if np.isnan(moved).any() else float(moved.max())


def draw_rows(grey: np.ndarray, corners: np.ndarray, columns: int, rows: int, caption: str) -> np.ndarray:
    """BGR ``(h, w, 3)`` image of ``grey`` with each row of ``corners`` ``(columns * rows, 2)`` pixels (OpenCV's
    order) drawn in green over the straight line through its two ends in red: a lens that bends lines shows as rows
    sagging off their red lines."""
    import cv2

    img = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    for row in corners.reshape(rows, columns, 2):
        a, b = row[0], row[-1]
        d = (b - a) / max(np.linalg.norm(b - a), 1e-9)
        reach = max(img.shape)  # the line drawn across the whole image
        cv2.line(img, tuple(np.round(a - reach * d).astype(int)), tuple(np.round(b + reach * d).astype(int)), (40, 40, 230), 1, cv2.LINE_AA)
        cv2.polylines(img, [np.round(row).astype(np.int32)], False, (40, 200, 40), 2, cv2.LINE_AA)
    cv2.rectangle(img, (0, img.shape[0] - 26), (img.shape[1], img.shape[0]), (255, 255, 255), cv2.FILLED)
    cv2.putText(img, caption, (6, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
    return img


@node("calibrate.checkerboard", version=3, inputs={},
      outputs={"camera": CAMERA, "report": REPORT, "picture": IMAGE}, params=CheckerboardParams)
def checkerboard(ctx):
    """Intrinsics K and distortion from a checkerboard clip (OpenCV), extrinsics of the first view; ``picture``
    (PNG): the view whose board reaches farthest out, as filmed and with the lens taken out."""
    import cv2

    p: CheckerboardParams = ctx.params
    obj = board_points(p.columns, p.rows, p.square_size)
    views: list[tuple[int, np.ndarray]] = []
    size = None
    n_seen = 0
    widest = None  # (reach px from the centre, index, grey image, corners) of the view reaching farthest out
    for i, grey in ctx.progress(iter_images(Path(p.path), p.step), desc="checkerboard"):
        n_seen += 1
        if size is None:
            size = (grey.shape[1], grey.shape[0])
        elif (grey.shape[1], grey.shape[0]) != size:
            raise NodeError(f"{p.path}: image {i} is {grey.shape[1]}x{grey.shape[0]}, the first was {size[0]}x{size[1]}")
        corners = find_corners(grey, p.columns, p.rows)
        if corners is not None:
            views.append((i, corners))
            reach = float(np.linalg.norm(corners.reshape(-1, 2) - (np.array(size) - 1) / 2.0, axis=-1).max())
            if widest is None or reach > widest[0]:  # only that image is kept (a long clip's views are not held)
                widest = (reach, i, grey, corners.reshape(-1, 2))
    if len(views) < 3:
        raise NodeError(
            f"{p.path}: the {p.columns}x{p.rows} board was found in {len(views)} of {n_seen} images; at least 3 are needed",
            hint="check columns/rows (inner corners, not squares) and that the whole board is visible, in several tilted poses",
        )
    if len(views) > p.max_views:
        keep = np.unique(np.linspace(0, len(views) - 1, p.max_views).round().astype(int))
        views = [views[k] for k in keep]
    model = "fisheye" if p.distortion == "fisheye" else "pinhole"
    rms, K, dist, rvecs, tvecs = calibrate_views(obj, [c for _, c in views], size, p.distortion, p.path)
    bend = bend_at_corners(K, dist, *size, model=model)
    kept = view_kept(K, dist, model, *size, 0.5 * (K[0, 0] + K[1, 1]))
    _, index, grey, corners = widest
    centre = (np.array(size) - 1) / 2.0
    reached = max(float(np.linalg.norm(c.reshape(-1, 2) - centre, axis=-1).max()) for _, c in views) / float(np.hypot(*centre))
    warnings = []
    if reached < BOARD_REACH_WARN and bend > 1.0:
        warnings.append(
            f"{p.path}: the boards reached {100 * reached:.0f} % of the way from the image's centre to its corners; "
            f"beyond, the lens's distortion ({bend:.0f} px at the corners) is extrapolated, and a wrong lens model "
            "fits the boards as well as the right one there: film the board near the frame's edges and corners too")
    for w in warnings:
        ctx.warn(w)
    flat = ideal_points(corners, K, dist, model, K)
    pair = np.hstack([
        draw_rows(grey, corners, p.columns, p.rows, f"image {index} as filmed: rows (green) against straight lines (red)"),
        draw_rows(straighten_image(grey, K, dist, model, K), flat, p.columns, p.rows,
                  f"lens taken out ({model}): f {K[0, 0]:.0f} px, k1 {dist[0]:.3f} k2 {dist[1]:.3f}, corners bent "
                  f"{bend:.1f} px, view kept {100 * kept:.0f} %, rms {rms:.2f} px"),
    ])
    _, png = cv2.imencode(".png", pair)
    picture = atomic_write_bytes(ctx.output_path("lens.png"), png.tobytes())
    R0, t0 = cv2.Rodrigues(np.asarray(rvecs[0], np.float64).reshape(3))[0], np.ravel(tvecs[0])
    if model == "fisheye":  # no pinhole distortion terms hold it: the camera of the straightened frames
        cam = Camera(K=centred_intrinsics(0.5 * (K[0, 0] + K[1, 1]), *size), R=R0, t=t0, width=size[0], height=size[1])
    else:
        cam = Camera(K=K, R=R0, t=t0, width=size[0], height=size[1], dist=dist)
    return {"camera": cam.to_model(), "report": {
        "method": "checkerboard",
        "model": model,  # OpenCV's lens model of fx..cy and dist (io.video's lens reads it)
        "rms_reprojection_px": float(rms),
        "views_used": len(views),
        "images_seen": n_seen,
        "first_view_index": int(views[0][0]),
        "fx_px": float(K[0, 0]), "fy_px": float(K[1, 1]), "cx_px": float(K[0, 2]), "cy_px": float(K[1, 2]),
        "width": int(size[0]), "height": int(size[1]),  # the frame size it holds for (io.video's lens checks it)
        "bend_px_at_corners": round(bend, 2) if np.isfinite(bend) else None,  # how far the lens moves the image's corners
        "view_kept_pct": round(100 * kept, 1),  # of the filmed frame, in the straightened frames
        "board_reach_pct": round(100 * reached, 1),  # farthest board corner, of the way from the centre to the corners
        "dist": dist.tolist(),
        "warnings": warnings,
    }, "picture": picture}


def calibrate_views(obj: np.ndarray, corners: list[np.ndarray], size: tuple[int, int], distortion: str, where) -> tuple:
    """``(rms px, K (3, 3), dist, rvecs, tvecs)`` from the board's object points ``obj`` ``(n, 3)`` metres seen at
    ``corners`` (one ``(n, 1, 2)`` pixel array per view) in ``size`` ``(w, h)`` images: ``cv2.calibrateCamera`` with
    the terms ``distortion`` names (dist ``(5,)`` k1 k2 p1 p2 k3), or ``cv2.fisheye.calibrate`` for ``fisheye``
    (dist ``(4,)`` k1..k4). A fit OpenCV refuses is a :class:`NodeError` naming ``where``."""
    import cv2

    if distortion == "fisheye":
        def flag(name: str) -> int:  # cv2.fisheye's own constants in OpenCV 4, the shared ones in OpenCV 5
            return getattr(cv2.fisheye, name, None) or getattr(cv2, name)

        # k3 k4 stay 0 (as k1k2 does for the pinhole model): free, they bend the lens's rim where no board reached
        flags = flag("CALIB_RECOMPUTE_EXTRINSIC") | flag("CALIB_FIX_SKEW") | flag("CALIB_FIX_K3") | flag("CALIB_FIX_K4")
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-9)
        try:
            rms, K, dist, rvecs, tvecs = cv2.fisheye.calibrate(
                [obj.reshape(1, -1, 3).astype(np.float64)] * len(corners),
                [c.reshape(1, -1, 2).astype(np.float64) for c in corners], size, None, None, flags=flags, criteria=criteria)
        except cv2.error as exc:
            raise NodeError(f"{where}: OpenCV's fisheye calibration failed on {len(corners)} views ({exc.err})",
                            hint="film the board in more poses, tilted and reaching into the frame's corners; or try "
                                 "distortion: k1k2 for a lens that is not a fisheye") from exc
        return rms, K, np.ravel(dist)[:4], rvecs, tvecs
    flags = {
        "none": cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3,
        "k1k2": cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3,
        "full": 0,
    }[distortion]
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera([obj] * len(corners), corners, size, None, None, flags=flags)
    return rms, K, np.concatenate([np.ravel(dist), np.zeros(5)])[:5], rvecs, tvecs
