"""The ``lens`` port: what a node found out about the camera's focal length before the take is solved."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class LensEstimate(BaseModel):
    """A focal length in pixels with its uncertainty, or none (``focal_px`` ``None``: nothing was found, and
    ``source`` says why). ``reconstruct.solve_take`` starts from it and keeps it as a prior unless the
    ``focal_px`` param is given."""

    model_config = ConfigDict(extra="forbid")

    focal_px: float | None = Field(None, gt=0, description="focal length, pixels (None: not found)")
    focal_sd_pct: float | None = Field(None, gt=0, description="its standard deviation, per cent")
    width: int = Field(gt=0, description="image width it refers to, pixels")
    height: int = Field(gt=0, description="image height it refers to, pixels")
    source: str = Field(description="how it was found, or why it was not")
    up_cam: list[float] | None = Field(None, min_length=3, max_length=3, description="the floor's up direction in "
                                       "the camera frame (x right, y down, z forward), unit, when the lines lie on a floor")
    up_sd_deg: float | None = Field(None, gt=0, description="its standard deviation, degrees")
