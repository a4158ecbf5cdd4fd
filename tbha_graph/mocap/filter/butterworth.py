"""``filter.butterworth``: zero-phase Butterworth low-pass of joint trajectories (FreeMoCap's smoother).

Second-order sections (``scipy.signal.butter(..., output="sos")``) run forwards and backwards
(``sosfiltfilt``), so there is no lag and the magnitude response is squared (the -3 dB point of the
designed filter becomes about -6 dB). Applied to every coordinate of every joint at once, along frames.
"""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..lowpass import butterworth_lowpass
from ..ports import MOTION
from ..bundles.motion import motion_joints, with_joints


class ButterworthParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    cutoff: float = Field(7.0, gt=0, description="low-pass cutoff frequency (below fps / 2)", json_schema_extra={"unit": "Hz"})
    order: int = Field(4, ge=1, le=8, description="filter order of the designed filter (doubled by forward-backward filtering)")


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
