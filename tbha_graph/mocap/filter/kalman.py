"""``filter.kalman``: constant-velocity Kalman filter with a Rauch-Tung-Striebel smoother per coordinate.

Every coordinate of every joint is an independent state ``(position m, velocity m/s)`` driven by white
acceleration noise (``accel_sigma``, m/s²) and observed with noise ``measurement_sigma`` (m). Joints the
tracker did not see in a frame (``tracked`` False) are observed with ``untracked_factor`` times more
noise, so the filter leans on its prediction there. ``smooth`` runs the RTS backward pass (no lag, uses
future frames); without it the filter is causal (online) and lags on fast motion.
Vectorised over the 48 coordinates; one short loop over frames.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import MOTION
from ..bundles.motion import motion_joints, with_joints


class KalmanParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    accel_sigma: float = Field(20.0, gt=0, description="std of the random acceleration (process noise)", json_schema_extra={"unit": "m/s²"})
    measurement_sigma: float = Field(0.015, gt=0, description="std of a tracked joint's position error", json_schema_extra={"unit": "m"})
    untracked_factor: float = Field(10.0, ge=1, description="measurement std multiplier for joints not tracked in a frame")
    smooth: bool = Field(True, description="run the RTS backward pass (zero lag, offline); false: causal filter only")


def kalman_smooth(
    x: np.ndarray, fps: float, accel_sigma: float, measurement_sigma: float,
    weights: np.ndarray | None = None, smooth: bool = True,
) -> np.ndarray:
    """Filter ``x`` ``(n_frames, S)`` (S independent series) along frames; ``weights`` ``(n_frames, S)``
    multiply the measurement std per sample (1 = nominal). Returns the filtered/smoothed positions."""
    x = np.asarray(x, dtype=np.float64)
    n, s = x.shape
    if n < 2:
        return x.copy()
    dt = 1.0 / fps
    F = np.array([[1.0, dt], [0.0, 1.0]])
    q = accel_sigma**2
    Q = q * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    r = (measurement_sigma * (np.ones_like(x) if weights is None else weights)) ** 2  # (n, S)
    m = np.zeros((n, s, 2))
    P = np.zeros((n, s, 2, 2))
    mp = np.zeros((n, s, 2))
    Pp = np.zeros((n, s, 2, 2))
    mean, cov = np.stack([x[0], np.zeros(s)], axis=-1), np.tile(np.diag([r[0].max(), 4.0])[None], (s, 1, 1))
    for k in range(n):
        if k:
            mean = mean @ F.T
            cov = F @ cov @ F.T + Q
        mp[k], Pp[k] = mean, cov
        innov = x[k] - mean[:, 0]
        S_ = cov[:, 0, 0] + r[k]
        K = cov[:, :, 0] / S_[:, None]  # (S, 2)
        mean = mean + K * innov[:, None]
        cov = cov - K[:, :, None] * cov[:, 0, None, :]
        m[k], P[k] = mean, cov
    if not smooth:
        return m[:, :, 0]
    out = m.copy()
    for k in range(n - 2, -1, -1):
        C = P[k] @ F.T @ np.linalg.inv(Pp[k + 1])  # (S, 2, 2)
        out[k] = m[k] + np.einsum("sij,sj->si", C, out[k + 1] - mp[k + 1])
    return out[:, :, 0]


@node("filter.kalman", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION}, params=KalmanParams)
def kalman(ctx, motion):
    """Constant-velocity Kalman filter + RTS smoother of every joint; untracked joints trust the prediction."""
    joints, fps = motion_joints(motion)
    p = ctx.params
    n = joints.shape[0]
    tracked = np.asarray(motion.get("tracked", np.ones(joints.shape[:2], bool)), dtype=bool)
    w = np.where(tracked, 1.0, p.untracked_factor)[:, :, None].repeat(3, axis=2).reshape(n, -1)
    out = kalman_smooth(joints.reshape(n, -1), fps, p.accel_sigma, p.measurement_sigma, w, p.smooth)
    return {"motion": with_joints(motion, out.reshape(joints.shape))}
