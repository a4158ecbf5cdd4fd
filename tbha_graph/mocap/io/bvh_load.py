"""Node ``io.bvh_load``: read a BVH file and map its skeleton onto the 16 TBHA joints (a ``MOTION``)."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ...core.node import InputPath, node
from ..ports import MOTION
from .skeleton_map import motion16_from_bvh


class BvhLoadParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="BVH file to read (relative paths start from the pipeline file's folder)")
    mapping: str = Field(
        "cmu",
        min_length=1,
        description="skeleton mapping: a bundled name ('cmu') or the path of a mapping YAML file "
        "(TBHA joint -> BVH joint, units_to_metres, axes)",
    )
    units_to_metres: float | None = Field(
        None, gt=0, description="metres per BVH unit; overrides the mapping's value", json_schema_extra={"unit": "m"}
    )


@node("io.bvh_load", version=1, outputs={"motion": MOTION}, params=BvhLoadParams)
def bvh_load(ctx):
    """Read a BVH motion file and give the 16 TBHA joints' positions in metres (world frame, y up)."""
    p = ctx.params
    return {"motion": motion16_from_bvh(p.path, p.mapping, p.units_to_metres)}
