"""The ``video`` port: a reference to (a frame range of) a video file, streamed by its consumers."""
from __future__ import annotations

from pydantic import BaseModel, Field


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

    @property
    def n_frames(self) -> int:
        return self.stop - self.start
