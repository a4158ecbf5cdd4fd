"""Node ``synth.camera``: place a pinhole camera (world frame metres, y up) looking at the actor.

The default suits the rendered samples: 4.6 m in front of the actor (the actor faces +z in the
T-pose, so the camera stands at +z looking towards -z), slightly to the actor's left and a little
above chest height looking down at the body, so the whole body fits in 640x480 with margin. The small
side and down angles keep the torso plane from being parallel to the image, which the coplanar Tsai
calibration needs (it cannot separate focal length and distance for a fronto-parallel plane).
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.node import node
from ..camera import Camera
from ..ports import CAMERA


class CameraParams(BaseModel):
    """Where the camera is, where it looks, its focal length and image size."""

    model_config = ConfigDict(extra="forbid")

    eye: tuple[float, float, float] = Field((0.8, 1.45, 4.6), description="camera centre, world", json_schema_extra={"unit": "m"})
    target: tuple[float, float, float] = Field((0.0, 0.95, 0.0), description="point looked at, world", json_schema_extra={"unit": "m"})
    focal_px: float = Field(700.0, gt=0, le=1e5, description="focal length", json_schema_extra={"unit": "px"})
    width: int = Field(640, ge=16, le=8192, description="image width", json_schema_extra={"unit": "px"})
    height: int = Field(480, ge=16, le=8192, description="image height", json_schema_extra={"unit": "px"})

    @model_validator(mode="after")
    def _distinct(self) -> "CameraParams":
        d = np.subtract(self.target, self.eye)
        n = float(np.linalg.norm(d))
        if n < 1e-6:
            raise ValueError("eye and target are the same point: the camera has no viewing direction")
        if abs(d[1]) / n > 0.999:
            raise ValueError("the camera looks straight up or down: world up (y) must not be the viewing direction")
        return self


@node("synth.camera", version=1, outputs={"camera": CAMERA}, params=CameraParams)
def camera(ctx):
    """Place a pinhole camera at `eye` looking at `target` (world metres, y up), no lens distortion."""
    p: CameraParams = ctx.params
    cam = Camera.look_at(p.eye, p.target, focal_px=p.focal_px, width=p.width, height=p.height)
    return {"camera": cam.to_model()}
