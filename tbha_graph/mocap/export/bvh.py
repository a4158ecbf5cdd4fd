"""Node ``export.bvh``: write joint rotations of the 16-joint model as a BVH file, and check it.

The file uses the names of :data:`tbha_graph.mocap.skeleton.JOINT_NAMES` (``ROOT hips``), y up, the
actor facing +z in the rest T-pose, one Euler order for every joint (``rotation_order``, default ZXY),
6 channels on the root and 3 on every other joint, End Sites on the leaf joints (head, wrists, ankles)
from ``end_offsets``. Lengths are metres times ``scale``. After writing, the node reads the file back
and compares forward kinematics of the file with that of its input: a joint off by more than 0.1 mm on
any frame fails the node (a self-check, not a warning).
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ...core.types import File
from ..io.bvh import bvh_from_local, bvh_positions, end_site_positions, read_bvh, write_bvh
from ..kinematics import forward_kinematics, quat_apply
from ..ports import ROTATIONS
from ..skeleton import JOINT_NAMES, PARENTS

#: Largest allowed difference between the written file and the input, metres.
SELF_CHECK_TOLERANCE_M = 1e-4


class ExportBvhParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    rotation_order: str = Field(
        "ZXY",
        pattern=r"^(XYZ|XZY|YXZ|YZX|ZXY|ZYX)$",
        description="Euler channel order written for every joint (intrinsic, as in BVH), e.g. ZXY or ZYX",
    )
    precision: int = Field(6, ge=1, le=12, description="decimals written for offsets and channel values")
    scale: float = Field(
        1.0, gt=0, description="file units per metre: 1 writes metres, 100 centimetres",
        json_schema_extra={"unit": "file units / m"},
    )


def _checked_inputs(rot: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Validate and normalise the ROTATIONS bundle; NodeError naming the frame/joint otherwise."""
    local = np.asarray(rot["local_quat"], dtype=np.float64)
    root = np.asarray(rot["root_position"], dtype=np.float64)
    offsets = np.asarray(rot["offsets"], dtype=np.float64)
    ends = np.asarray(rot["end_offsets"], dtype=np.float64)
    fps = float(rot["fps"])
    n = local.shape[0]
    if n == 0:
        raise NodeError("the rotations have no frames: nothing to export")
    if root.shape != (n, 3):
        raise NodeError(f"root_position has shape {root.shape}, expected ({n}, 3) to match local_quat")
    if not (np.isfinite(fps) and fps > 0):
        raise NodeError(f"fps is {fps}, expected a positive number of frames per second")
    for name, arr in (("offsets", offsets), ("end_offsets", ends)):
        if not np.isfinite(arr).all():
            j = int(np.argwhere(~np.isfinite(arr))[0, 0])
            raise NodeError(f"{name} of joint '{JOINT_NAMES[j]}' is not finite")
    bad = ~np.isfinite(root).all(axis=1)
    if bad.any():
        raise NodeError(f"root_position is not finite on frame {int(np.flatnonzero(bad)[0])}",
                        hint="fill gaps (e.g. with a smoothing/interpolation node) before exporting")
    norm = np.linalg.norm(local, axis=-1)
    bad = ~np.isfinite(norm) | (norm < 1e-6)
    if bad.any():
        f, j = (int(x) for x in np.argwhere(bad)[0])
        raise NodeError(f"local_quat of joint '{JOINT_NAMES[j]}' on frame {f} is not a rotation ({local[f, j]})",
                        hint="fill gaps (e.g. with a smoothing/interpolation node) before exporting")
    return local / norm[..., None], root, offsets, ends, fps


@node("export.bvh", version=1, inputs={"rotations": ROTATIONS},
      outputs={"bvh": File(kind="bvh", suffix=".bvh")}, params=ExportBvhParams)
def export_bvh(ctx, rotations):
    """Write the 16-joint rotations as a BVH file (y up, facing +z) and verify it by reading it back."""
    p = ctx.params
    local, root, offsets, ends, fps = _checked_inputs(rotations)
    s = p.scale
    bvh = bvh_from_local(JOINT_NAMES, PARENTS, offsets * s, ends * s, local, root * s, 1.0 / fps, order=p.rotation_order)
    path = write_bvh(ctx.output_path("motion.bvh"), bvh, precision=p.precision)

    # self-check: the file, read back, must put every joint (and End Site) where the input does
    back = read_bvh(path)
    want, world = forward_kinematics(PARENTS, offsets, local, root)
    got = bvh_positions(back) / s
    err = np.linalg.norm(got - want, axis=-1)
    got_ends = end_site_positions(back)
    for j, end in got_ends.items():
        want_end = want[:, j] + quat_apply(world[:, j], ends[j])
        err[:, j] = np.maximum(err[:, j], np.linalg.norm(end / s - want_end, axis=-1))
    f, j = np.unravel_index(int(np.argmax(err)), err.shape)
    worst = float(err[f, j])
    if worst > SELF_CHECK_TOLERANCE_M:
        raise NodeError(
            f"self-check failed: reading {path.name} back puts joint '{JOINT_NAMES[j]}' {worst * 1000:.3f} mm "
            f"from the input on frame {f} (allowed {SELF_CHECK_TOLERANCE_M * 1000:.1f} mm)",
            hint="raise 'precision' (decimals written) or, for small units, 'scale'",
        )
    ctx.log(f"wrote {back.n_frames} frames; self-check: worst joint off by {worst * 1000:.5f} mm")
    return {"bvh": path}
