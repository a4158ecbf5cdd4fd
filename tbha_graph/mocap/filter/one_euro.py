"""``filter.one_euro``: the One Euro filter (Casiez, Roussel & Vogel, CHI 2012), as used by VIBE.

An exponential smoother whose cutoff rises with speed: ``fc = min_cutoff + beta * |dx/dt|`` (speed of
the joint in m/s, from a low-pass of the derivative at ``d_cutoff``), smoothing factor
``alpha = r / (1 + r)`` with ``r = 2 pi fc / fps``. Slow joints are smoothed hard (jitter removed),
fast joints lightly (little lag). Causal: frame t depends on frames <= t only, so it also suits live use.
The speed is the norm of each joint's 3D velocity, so all three coordinates of a joint share one cutoff.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import MOTION
from ..bundles.motion import motion_joints, with_joints


class OneEuroParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    min_cutoff: float = Field(1.0, gt=0, description="cutoff frequency when the joint is still", json_schema_extra={"unit": "Hz"})
    beta: float = Field(1.0, ge=0, description="cutoff increase per unit of speed", json_schema_extra={"unit": "Hz/(m/s)"})
    d_cutoff: float = Field(1.0, gt=0, description="cutoff of the low-pass on the speed estimate", json_schema_extra={"unit": "Hz"})


def _alpha(cutoff: np.ndarray | float, fps: float) -> np.ndarray | float:
    r = 2.0 * np.pi * np.asarray(cutoff) / fps
    return r / (1.0 + r)


def one_euro_filter(x: np.ndarray, fps: float, min_cutoff: float = 1.0, beta: float = 1.0, d_cutoff: float = 1.0) -> np.ndarray:
    """One Euro filter of points ``x`` ``(n_frames, ..., 3)`` along axis 0 (a frame loop, vectorised
    over points); the speed for the adaptive cutoff is the norm over the last axis. Returns the same shape."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty_like(x)
    if x.shape[0] == 0:
        return out
    out[0] = x[0]
    a_d = _alpha(d_cutoff, fps)
    prev = x[0].copy()
    dx_hat = np.zeros_like(x[0])
    for t in range(1, x.shape[0]):
        dx = (x[t] - prev) * fps
        dx_hat += a_d * (dx - dx_hat)
        speed = np.sqrt(np.sum(dx_hat * dx_hat, axis=-1, keepdims=True))
        a = _alpha(min_cutoff + beta * speed, fps)
        prev = prev + a * (x[t] - prev)
        out[t] = prev
    return out


@node("filter.one_euro", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION}, params=OneEuroParams)
def one_euro(ctx, motion):
    """One Euro filter of every joint (speed-adaptive low-pass: removes jitter when still, little lag when fast)."""
    joints, fps = motion_joints(motion)
    p = ctx.params
    return {"motion": with_joints(motion, one_euro_filter(joints, fps, p.min_cutoff, p.beta, p.d_cutoff))}
