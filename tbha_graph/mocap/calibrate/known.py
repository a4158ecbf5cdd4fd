"""``calibrate.known``: a camera read from a file (a studio calibration, or the renderer's ground truth).

Accepted files:

* ``.yaml`` / ``.yml`` / ``.json``: a mapping with ``K`` (3x3 px), ``R`` (3x3, world -> camera), ``t`` (3, metres),
  ``width``, ``height`` (px) and optional ``dist`` (k1, k2, p1, p2, k3); the mapping may also sit under a
  top-level ``camera:`` key.
* ``.npz`` (e.g. the renderer's ``ground_truth.npz``): arrays with the same names (other arrays are ignored).

Conventions are those of :mod:`tbha_graph.mocap.camera` (Xc = R Xw + t, camera x right, y down, z forward).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ...core.npzfile import read_npz
from ...core.yamlfile import read_data_file
from ..camera import Camera
from ..ports import CAMERA, REPORT

REQUIRED = ("K", "R", "t", "width", "height")


class KnownParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="camera file: YAML/JSON mapping or .npz with K, R, t, width, height[, dist]")
    rotation_tolerance: float = Field(1e-4, gt=0, le=0.1, description="largest allowed |R R^T - I| entry")


def _numbers_only(x) -> bool:
    """A number or nested lists of numbers, written as numbers (not true/false, not "1.5")."""
    if isinstance(x, list):
        return all(_numbers_only(v) for v in x)
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _read_mapping(path: Path) -> dict:
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return read_npz(path, "camera file", keys=REQUIRED + ("dist",))  # no pickle, every member's CRC checked
    if suffix not in (".yaml", ".yml", ".json"):
        raise NodeError(f"{path}: unknown camera file type {suffix!r}", hint="use .yaml, .yml, .json or .npz")
    return _camera_mapping(path, read_data_file(path, "camera file", NodeError))  # safe YAML or JSON, errors with line


def _camera_mapping(path: Path, data) -> dict:
    if isinstance(data, dict) and isinstance(data.get("camera"), dict):
        data = data["camera"]
    if not isinstance(data, dict):
        raise NodeError(f"{path}: expected a mapping with keys {', '.join(REQUIRED)}, got {type(data).__name__}")
    return data


def read_camera_file(path: Path, rotation_tolerance: float = 1e-4) -> Camera:
    """Read and check a camera file (see module docstring). Raises :class:`NodeError` naming the file and key."""
    path = Path(path)
    if not path.is_file():
        raise NodeError(f"camera file {path} does not exist", hint="check the path (relative paths are relative to the pipeline file)")
    data = _read_mapping(path)
    missing = [k for k in REQUIRED if k not in data]
    if missing:
        raise NodeError(f"{path}: missing key(s) {', '.join(missing)} (present: {', '.join(sorted(map(str, data))) or 'none'})",
                        hint=f"a camera file needs {', '.join(REQUIRED)} and optionally dist")
    shapes = {"K": (3, 3), "R": (3, 3), "t": (3,), "width": (), "height": (), "dist": (5,)}
    arrays = {}
    for key, shape in shapes.items():
        if key not in data:
            continue
        value = data[key]
        numeric = value.dtype.kind in "iuf" if isinstance(value, np.ndarray) else _numbers_only(value)
        if not numeric:  # numpy would quietly take true as 1 and "800" as 800.0
            raise NodeError(f"{path}: key {key!r} is not numeric: {value!r}")
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise NodeError(f"{path}: key {key!r} is not numeric: {data[key]!r}") from None
        if key == "t" and a.shape in ((3, 1), (1, 3)):
            a = a.reshape(3)
        if key == "dist":
            a = a.reshape(-1)
            if a.size not in (4, 5, 8) or (a.size == 8 and np.any(a[5:])):
                raise NodeError(f"{path}: dist must be (k1, k2, p1, p2[, k3]); got {a.size} values",
                                hint="the rational terms k4..k6 are not supported")
            a = np.concatenate([a, np.zeros(1)])[:5] if a.size == 4 else a[:5]
        if a.shape != shape:
            raise NodeError(f"{path}: key {key!r} has shape {a.shape}, expected {shape}")
        if not np.isfinite(a).all():
            raise NodeError(f"{path}: key {key!r} holds a non-finite value")
        arrays[key] = a
    R = arrays["R"]
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    if err > rotation_tolerance or np.linalg.det(R) < 0:
        raise NodeError(f"{path}: R is not a rotation (|R R^T - I| = {err:.2g}, det = {np.linalg.det(R):.3g})",
                        hint="R must be the world -> camera rotation matrix")
    K = arrays["K"]
    if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1.0) > 1e-9:
        raise NodeError(f"{path}: K is not an intrinsics matrix (fx, fy > 0, K[2][2] = 1): {K.tolist()}")
    width, height = int(arrays["width"]), int(arrays["height"])
    if width != arrays["width"] or height != arrays["height"]:
        raise NodeError(f"{path}: image size {arrays['width']:g}x{arrays['height']:g} is not a whole number of pixels")
    if width <= 0 or height <= 0:
        raise NodeError(f"{path}: image size {width}x{height} is not positive")
    return Camera(K=K, R=R, t=arrays["t"], width=width, height=height, dist=arrays.get("dist", np.zeros(5)))


@node("calibrate.known", version=1, inputs={}, outputs={"camera": CAMERA, "report": REPORT}, params=KnownParams)
def known(ctx):
    """Camera (K, R, t, image size, distortion) read from a YAML/JSON/npz file."""
    cam = read_camera_file(ctx.params.path, ctx.params.rotation_tolerance)
    c = cam.center
    return {"camera": cam.to_model(), "report": {
        "method": "known", "file": str(ctx.params.path), "focal_px": float(cam.K[0, 0]),
        "camera_x_m": float(c[0]), "camera_height_m": float(c[1]), "camera_z_m": float(c[2]),
    }}
