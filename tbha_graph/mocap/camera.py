"""Pinhole camera model shared by the renderer, the calibrators and the reconstructors.

Conventions (the one place they are defined):

* World frame: metres, y up (see :mod:`tbha_graph.mocap.skeleton`).
* Camera frame: metres, **x right, y down, z forward** (OpenCV's convention).
  A world point ``Xw`` maps to ``Xc = R @ Xw + t`` (R, t: world -> camera, as in Tsai and OpenCV).
* Pixels: ``(u, v)`` from the **top-left corner** of the image, u to the right, v down; the centre of
  the top-left pixel is (0, 0). ``u = fx * Xc / Zc + cx``, ``v = fy * Yc / Zc + cy``.
* Lens distortion, when present, is OpenCV's ``(k1, k2, p1, p2, k3)`` model.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydantic import BaseModel, Field


def centred_intrinsics(focal_px: float, width: int, height: int) -> np.ndarray:
    """``(3, 3)`` intrinsics of an ideal camera: focal length ``focal_px`` pixels, square pixels, the principal point
    at the image centre ``((width - 1) / 2, (height - 1) / 2)``."""
    return np.array([[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


class CameraModel(BaseModel):
    """A camera as data (what flows between nodes and is written to files): see :class:`Camera`."""

    K: list[list[float]] = Field(description="3x3 intrinsics, pixels")
    R: list[list[float]] = Field(description="3x3 rotation, world -> camera")
    t: list[float] = Field(description="translation, world -> camera, metres")
    width: int = Field(gt=0, description="image width, pixels")
    height: int = Field(gt=0, description="image height, pixels")
    dist: list[float] = Field(default_factory=lambda: [0.0] * 5, description="OpenCV distortion (k1, k2, p1, p2, k3)")

    def camera(self) -> "Camera":
        return Camera.from_dict(self.model_dump())


@dataclass(frozen=True)
class Camera:
    """Intrinsics ``K`` (3, 3) pixels, extrinsics ``R`` (3, 3) and ``t`` (3,) metres (world -> camera),
    image size in pixels and optional distortion ``dist`` (5,)."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", np.asarray(self.K, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "R", np.asarray(self.R, dtype=np.float64).reshape(3, 3))
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.float64).reshape(3))
        object.__setattr__(self, "dist", np.asarray(self.dist, dtype=np.float64).reshape(-1))

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def look_at(
        cls,
        eye,
        target,
        *,
        focal_px: float,
        width: int,
        height: int,
        up=(0.0, 1.0, 0.0),
    ) -> "Camera":
        """A camera at ``eye`` (world, metres) looking at ``target``, with world ``up`` appearing up in the
        image. Principal point at the image centre ``((width - 1) / 2, (height - 1) / 2)``."""
        eye = np.asarray(eye, dtype=np.float64)
        z = np.asarray(target, dtype=np.float64) - eye
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, dtype=np.float64))  # image right (x = y_down x z = z x up)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        t = -R @ eye
        K = centred_intrinsics(focal_px, width, height)
        return cls(K=K, R=R, t=t, width=int(width), height=int(height))

    # --- geometry -----------------------------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        """Optical centre in world coordinates, shape (3,) metres."""
        return -self.R.T @ self.t

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """World points ``(..., 3)`` metres -> camera frame ``(..., 3)`` metres (x right, y down, z forward)."""
        return np.asarray(points_world, dtype=np.float64) @ self.R.T + self.t

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points ``(..., 3)`` -> world frame ``(..., 3)`` metres."""
        return (np.asarray(points_cam, dtype=np.float64) - self.t) @ self.R

    def project_camera(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points ``(..., 3)`` -> pixels ``(..., 2)`` (top-left origin), distortion applied."""
        p = np.asarray(points_cam, dtype=np.float64)
        x = p[..., 0] / p[..., 2]
        y = p[..., 1] / p[..., 2]
        if np.any(self.dist):
            k1, k2, p1, p2, k3 = (list(self.dist) + [0.0] * 5)[:5]
            r2 = x * x + y * y
            radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
            x, y = (
                x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
            )
        K = self.K
        return np.stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]], axis=-1)

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """World points ``(..., 3)`` metres -> pixels ``(..., 2)``, e.g. ``(n_frames, 16, 3) -> (n_frames, 16, 2)``."""
        return self.project_camera(self.to_camera(points_world))

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels ``(..., 2)`` -> unit ray directions ``(..., 3)`` in the camera frame (no undistortion)."""
        px = np.asarray(pixels, dtype=np.float64)
        Kinv = np.linalg.inv(self.K)
        h = np.concatenate([px, np.ones(px.shape[:-1] + (1,))], axis=-1) @ Kinv.T
        return h / np.linalg.norm(h, axis=-1, keepdims=True)

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Boolean mask ``(...)``: pixel lies inside the image rectangle."""
        px = np.asarray(pixels)
        return (px[..., 0] >= -0.5) & (px[..., 0] <= self.width - 0.5) & (px[..., 1] >= -0.5) & (px[..., 1] <= self.height - 0.5)

    # --- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-able dict (lists of floats)."""
        return {
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "width": self.width,
            "height": self.height,
            "dist": self.dist.tolist(),
        }

    def to_model(self) -> CameraModel:
        return CameraModel(**self.to_dict())

    @classmethod
    def from_dict(cls, d: dict) -> "Camera":
        return cls(K=d["K"], R=d["R"], t=d["t"], width=d["width"], height=d["height"], dist=d.get("dist", np.zeros(5)))
