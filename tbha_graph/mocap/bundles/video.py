"""The ``video`` port: a reference to (a frame range of) a video file, streamed by its consumers."""
from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class LensUndistortion(BaseModel):
    """A lens calibration (``pipelines/checkerboard.yaml``'s ``lens.json``) applied to every frame as it is read:
    the frame is remapped from the calibrated camera ``K`` with ``dist`` to an ideal pinhole camera of focal length
    ``focal_px`` with square pixels and its principal point at the image centre ``((w - 1) / 2, (h - 1) / 2)``, the
    camera every later stage assumes. ``K`` refers to the clip's frames (after ``scale``). ``model`` is OpenCV's
    lens model the file was calibrated with: ``pinhole`` (``dist`` k1 k2 p1 p2 k3, ``cv2.undistort``'s) or
    ``fisheye`` (``dist`` k1 k2 k3 k4 of the angle, ``cv2.fisheye``'s: an action camera's widest modes)."""

    model_config = ConfigDict(extra="forbid")

    K: list[list[float]] = Field(description="3x3 intrinsics of the calibrated camera at the clip's frame size, pixels")
    model: Literal["pinhole", "fisheye"] = Field("pinhole", description="OpenCV lens model of K and dist")
    dist: list[float] = Field(min_length=4, max_length=5, description="OpenCV distortion: k1 k2 p1 p2 k3 (pinhole) "
                              "or k1 k2 k3 k4 (fisheye)")
    focal_px: float = Field(gt=0, description="focal length of the frames as read, pixels (the mean of K's fx and fy, "
                            "or shorter to keep the filmed frame's width: io.video's lens_view)")
    source: str = Field(description="the lens file it came from")

    @model_validator(mode="after")
    def _terms_fit_the_model(self) -> "LensUndistortion":
        need = 4 if self.model == "fisheye" else 5
        if len(self.dist) != need:
            raise ValueError(f"a {self.model} lens has {need} distortion terms, got {len(self.dist)}")
        return self


class VideoClip(BaseModel):
    """A reference to (a frame range of) a video file: what ``io.video`` outputs. Consumers stream
    frames with :func:`tbha_graph.mocap.io.video.iter_frames`; the file is never copied or loaded whole."""

    path: str = Field(description="absolute path of the video file")
    sha256: str = Field(description="content hash of the file (part of downstream cache keys)")
    start: int = Field(0, ge=0, description="first frame index (inclusive)")
    stop: int = Field(description="last frame index (exclusive)")
    scale: float = Field(1.0, gt=0, le=1, description="downscale factor applied to frames")
    fps: float = Field(gt=0, description="frames per second")
    width: int = Field(description="frame width after scaling, pixels")
    height: int = Field(description="frame height after scaling, pixels")
    lens: LensUndistortion | None = Field(None, description="lens distortion removed from every frame as it is read "
                                          "(io.video's lens param); None: the frames as the file holds them")

    @property
    def n_frames(self) -> int:
        return self.stop - self.start
