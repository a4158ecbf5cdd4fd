"""``filter.butterworth``: zero-phase Butterworth low-pass of joint trajectories (FreeMoCap's smoother).

Second-order sections (``scipy.signal.butter(..., output="sos")``) run forwards and backwards
(``sosfiltfilt``), so there is no lag and the magnitude response is squared (the -3 dB point of the
designed filter becomes about -6 dB). Applied to every coordinate of every joint at once, along frames.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..ports import MOTION
from .common import motion_joints, with_joints


class ButterworthParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    cutoff: float = Field(7.0, gt=0, description="low-pass cutoff frequency (below fps / 2)", json_schema_extra={"unit": "Hz"})
    order: int = Field(4, ge=1, le=8, description="filter order of the designed filter (doubled by forward-backward filtering)")


def butterworth_lowpass(x: np.ndarray, fps: float, cutoff: float, order: int = 4) -> np.ndarray:
    """Zero-phase low-pass of ``x`` ``(n_frames, ...)`` along axis 0; ``fps`` and ``cutoff`` in Hz.

    Clips shorter than the default padding are padded as much as they allow (``n_frames - 1``); a single
    frame is returned unchanged. Raises ``ValueError`` if ``cutoff >= fps / 2``.
    """
    from scipy.signal import butter, sosfiltfilt

    if cutoff >= fps / 2:
        raise ValueError(f"cutoff {cutoff} Hz must be below the Nyquist frequency {fps / 2} Hz")
    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] < 2:
        return x.copy()
    sos = butter(order, cutoff, btype="low", fs=fps, output="sos")
    default_pad = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    return sosfiltfilt(sos, x, axis=0, padlen=min(default_pad, x.shape[0] - 1))


@node("filter.butterworth", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION}, params=ButterworthParams)
def butterworth(ctx, motion):
    """Zero-phase Butterworth low-pass of every joint trajectory (default 7 Hz, order 4, like FreeMoCap)."""
    joints, fps = motion_joints(motion)
    p = ctx.params
    if p.cutoff >= fps / 2:
        raise NodeError(
            f"filter.butterworth: cutoff {p.cutoff:g} Hz is not below half the frame rate ({fps:.4g} fps -> {fps / 2:.4g} Hz)",
            hint=f"set a cutoff below {fps / 2:.4g} Hz, e.g. --set {ctx.node_id}.cutoff={min(7.0, round(fps / 4, 1)):g}",
        )
    return {"motion": with_joints(motion, butterworth_lowpass(joints, fps, p.cutoff, p.order))}
