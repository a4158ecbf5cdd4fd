"""Nodes of the example plugin. Every module-level @node here is registered by tbha-graph."""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tbha_graph.core import Array, node


class MovingAverageParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    window: int = Field(5, ge=1, description="window length", json_schema_extra={"unit": "frames"})


@node(
    "example.moving_average",
    version=1,
    inputs={"x": Array("float", ("n_frames", None, None))},
    outputs={"y": Array("float64", ("n_frames", None, None))},
    params=MovingAverageParams,
)
def moving_average(ctx, x):
    """Centred moving average along the first (frame) axis; edges use a shorter window.

    Works on any ``(n_frames, ...)`` float array, e.g. joint positions ``(n_frames, 16, 3)`` metres.
    """
    w = ctx.params.window
    x = np.asarray(x, dtype=np.float64)
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), x]), axis=0)
    n = x.shape[0]
    lo = np.clip(np.arange(n) - w // 2, 0, n)
    hi = np.clip(np.arange(n) + (w - w // 2), 0, n)
    shape = (n,) + (1,) * (x.ndim - 1)
    return (c[hi] - c[lo]) / (hi - lo).reshape(shape)
