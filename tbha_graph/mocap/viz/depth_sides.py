"""``viz.depth_sides``: the depth-flip timeline of ``reconstruct.temporal_ray_sphere`` as a PNG strip.

One row per limb joint, one column per frame: blue where the joint was placed nearer the camera than
the joint it hangs from (front), orange where farther (back), grey for torso joints. A wrong side shows
as a short block of the other colour; pin it with the reconstructor's ``overrides`` param.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import IMAGE, SIDES
from ..skeleton import JOINT_NAMES, N_JOINTS
from ...core.figure import new_figure, save_png


class DepthSidesParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    dpi: int = Field(110, ge=50, le=400, description="resolution of the PNG", json_schema_extra={"unit": "dots/inch"})


@node(
    "viz.depth_sides",
    version=1,
    inputs={"sides": SIDES},
    outputs={"png": IMAGE},
    params=DepthSidesParams,
)
def depth_sides(ctx, sides):
    """Depth-flip timeline: which side (front/back of its parent) every limb joint took on every frame."""
    s = np.asarray(sides["sides"])
    rows = [j for j in range(N_JOINTS) if (s[:, j] != 0).any()]
    fps = float(sides.get("fps", 30.0))
    rgb = np.empty((len(rows), s.shape[0], 3))
    for r, j in enumerate(rows):
        rgb[r] = np.where((s[:, j] < 0)[:, None], [0.22, 0.45, 0.85], np.where((s[:, j] > 0)[:, None], [0.95, 0.55, 0.15], [0.8, 0.8, 0.8]))
    fig = new_figure(10, 0.32 * len(rows) + 1.2)
    ax = fig.add_subplot(1, 1, 1)
    ax.imshow(rgb, aspect="auto", interpolation="nearest", extent=(0, s.shape[0], len(rows), 0))
    ax.set_yticks(np.arange(len(rows)) + 0.5, [JOINT_NAMES[j] for j in rows], fontsize=8)
    ax.set_xlabel(f"frame ({fps:g} fps)")
    ax.set_title("depth side per joint: blue = in front of its parent (nearer the camera), orange = behind", fontsize=9)
    return save_png(fig, ctx.output_path("depth_sides.png"), ctx.params.dpi)
