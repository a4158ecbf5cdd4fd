"""Node ``smpl.mesh``: SMPL meshes of a frame range written as one Wavefront OBJ.

Needs an SMPL model ``.npz`` (param ``model``; the official model is licensed and not shipped: without it
the node stops and says how to get and convert it). Each written frame is one object ``o frame_<index>``
with its 6890 vertices (metres, the parameters' world frame) and the model's triangles; Blender, MeshLab
and most viewers import the objects separately. Frames ``start, start + step, ... < stop``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.atomic import atomic_path
from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..ports import MESH, SMPL_PARAMS
from .model import HOW_TO_GET_THE_MODEL, load_model


class MeshParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    model: InputPath | None = Field(None, description="SMPL model .npz (made by python -m tbha_graph.mocap.smpl.convert)")
    start: int = Field(0, ge=0, description="first frame written", json_schema_extra={"unit": "frame"})
    stop: int | None = Field(None, ge=1, description="frame to stop before (None: the end)", json_schema_extra={"unit": "frame"})
    step: int = Field(10, ge=1, description="write every step-th frame", json_schema_extra={"unit": "frame"})
    max_frames: int = Field(200, ge=1, le=10000, description="refuse ranges with more frames than this (~0.5 MB per frame)")

    @model_validator(mode="after")
    def _range(self) -> "MeshParams":
        if self.stop is not None and self.stop <= self.start:
            raise ValueError(f"stop ({self.stop}) must be greater than start ({self.start})")
        return self


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, names: list[str]) -> None:
    """Write meshes ``vertices`` (k, V, 3) sharing ``faces`` (F, 3) as one OBJ with k objects, atomically."""
    path = Path(path)
    V = vertices.shape[1]
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as f:
        f.write("# SMPL meshes written by tbha-graph (smpl.mesh); metres, y up unless the parameters say otherwise\n")
        for i, (verts, name) in enumerate(zip(vertices, names)):
            f.write(f"o {name}\n")
            np.savetxt(f, verts, fmt="v %.6f %.6f %.6f")
            np.savetxt(f, faces + 1 + i * V, fmt="f %d %d %d")


@node("smpl.mesh", version=1, inputs={"smpl": SMPL_PARAMS}, outputs={"mesh": MESH}, params=MeshParams)
def mesh(ctx, smpl):
    """SMPL meshes (OBJ, one object per frame) of a frame range, with a user-supplied SMPL model file."""
    p = ctx.params
    if p.model is None:
        raise NodeError("no SMPL model file configured (param 'model')", hint=HOW_TO_GET_THE_MODEL)
    model = load_model(p.model)
    poses = np.asarray(smpl["poses"], dtype=np.float64)
    n = poses.shape[0]
    if p.start >= n:
        raise NodeError(f"start frame {p.start} is past the last frame ({n - 1})", hint="choose a smaller start")
    frames = np.arange(p.start, min(n, p.stop or n), p.step)
    if frames.size > p.max_frames:
        raise NodeError(f"{frames.size} frames requested, more than max_frames = {p.max_frames}",
                        hint="raise step, narrow start/stop, or raise max_frames")
    verts, _ = model.forward(poses[frames], smpl.get("betas"), np.asarray(smpl["trans"], dtype=np.float64)[frames])
    out = ctx.output_path("mesh.obj")
    write_obj(out, verts, model.faces, [f"frame_{int(i):06d}" for i in frames])
    return {"mesh": out}
