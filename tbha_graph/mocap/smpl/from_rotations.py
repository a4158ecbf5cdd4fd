"""Node ``smpl.from_rotations``: the 16-joint rotations as SMPL parameters, an AMASS-style bundle.

Output ``params`` (one ``.npz``, the keys AMASS uses for SMPL): ``poses`` (n, 72) axis-angle radians, joint
0 the global orientation (SMPL joint order, :data:`~tbha_graph.mocap.smpl.kintree.SMPL_JOINT_NAMES`);
``trans`` (n, 3) metres; ``betas`` (B,) shape coefficients; ``gender`` () str; ``mocap_framerate`` () float
frames/s. World frame: y up, the actor facing +z in the rest pose (``up: z`` re-expresses it z-up as AMASS's
raw files are). How the rotations map and what the model file adds: :mod:`tbha_graph.mocap.smpl.pose`.
"""
from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..ports import ROTATIONS, SMPL_PARAMS
from .pose import smpl_pose_from_rotations



class FromRotationsParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    betas: list[float] = Field(default_factory=lambda: [0.0] * 10, min_length=1, max_length=300,
                               description="SMPL shape coefficients (10 for the standard model; zeros = mean shape)")
    gender: Literal["neutral", "male", "female"] = Field("neutral", description="which SMPL model the parameters are for")
    model: InputPath | None = Field(None, description="SMPL model .npz (optional): aligns rest limb directions and puts the "
                                                      "pelvis on the root via its rest joints; see smpl.mesh for how to get it")
    spine: Literal["even", "top"] = Field("even", description="chest rotation split evenly over spine1-3, or all on spine3")
    up: Literal["y", "z"] = Field("y", description="up axis of the written world frame (z: AMASS raw files)")

    @field_validator("betas")
    @classmethod
    def _finite(cls, v: list[float]) -> list[float]:
        if not all(math.isfinite(b) for b in v):
            raise ValueError("betas must be finite numbers")
        return v


@node("smpl.from_rotations", version=1, inputs={"rotations": ROTATIONS}, outputs={"params": SMPL_PARAMS},
      params=FromRotationsParams)
def from_rotations(ctx, rotations):
    """SMPL pose parameters (n, 72), translation and shape from the 16-joint rotations (AMASS-style .npz)."""
    p = ctx.params
    lq = np.asarray(rotations["local_quat"], dtype=np.float64)
    if not np.isfinite(lq).all():
        f = int(np.argwhere(~np.isfinite(lq))[0][0])
        raise NodeError(f"rotations: frame {f} holds a non-finite quaternion", hint="check the rotation solver's output")
    rest = None
    betas = np.asarray(p.betas, dtype=np.float64)
    if p.model is not None:
        from .model import load_model

        model = load_model(p.model)
        rest = model.rest_joints(betas)
    poses, trans = smpl_pose_from_rotations(lq, rotations["root_position"], rest_joints=rest, spine=p.spine, up=p.up)
    return {"params": {
        "poses": poses, "trans": trans, "betas": betas, "gender": np.array(p.gender),
        "mocap_framerate": np.array(float(np.asarray(rotations["fps"]))),
    }}
