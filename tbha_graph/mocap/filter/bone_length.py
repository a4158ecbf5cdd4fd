"""``filter.bone_length``: force every bone to one length (its median over the clip, or a given length).

Walking the tree from the root outwards, each joint is placed at its (already corrected) parent plus
the bone length times the bone's current unit direction, so directions are kept and lengths become
exactly constant (FreeMoCap does the same). The root trajectory is unchanged. A bone of zero length in
some frames takes its direction from the nearest earlier frame where it had one (else the nearest
later frame, else the rest T-pose direction).
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from ...core.node import node
from ..ports import MOTION
from ..skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS, TPOSE_DIRECTIONS, measure_bone_lengths, topological_order
from ..bundles.motion import motion_joints, with_joints

#: bones shorter than this (metres) in a frame have no usable direction there
MIN_LENGTH = 1e-9


class BoneLengthParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    lengths: dict[str, float] = Field(
        default_factory=dict,
        description="bone lengths to impose instead of the clip's medians, by child joint name (e.g. left_elbow: 0.3)",
        json_schema_extra={"unit": "m"},
    )

    @field_validator("lengths")
    @classmethod
    def _known_bones(cls, v: dict[str, float]) -> dict[str, float]:
        for name, length in v.items():
            if name not in JOINT_INDEX or name == JOINT_NAMES[0]:
                raise ValueError(f"unknown bone {name!r}: bones are named by their child joint, one of {JOINT_NAMES[1:]}")
            if not (np.isfinite(length) and length >= 0):
                raise ValueError(f"bone {name!r}: length must be a finite number >= 0 metres, got {length}")
        return v


def _fill_directions(d: np.ndarray, ok: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Replace rows of ``d`` ``(n, 3)`` where ``ok`` is False by the nearest earlier valid row, then the
    nearest later one; ``fallback`` ``(3,)`` if no row is valid."""
    if ok.all():
        return d
    if not ok.any():
        return np.broadcast_to(fallback, d.shape).copy()
    idx = np.arange(d.shape[0])
    prev = np.maximum.accumulate(np.where(ok, idx, -1))
    nxt = np.minimum.accumulate(np.where(ok, idx, d.shape[0])[::-1])[::-1]
    src = np.where(prev >= 0, prev, nxt)
    return d[src]


def constant_bone_lengths(joints: np.ndarray, lengths: np.ndarray | None = None) -> np.ndarray:
    """Positions ``(n, 16, 3)`` metres with every bone set to ``lengths`` ``(16,)`` (default: the median
    measured length of each bone over the frames) along its current direction, root unchanged."""
    joints = np.asarray(joints, dtype=np.float64)
    if lengths is None:
        lengths = np.median(measure_bone_lengths(joints), axis=0)
    out = np.empty_like(joints)
    out[:, 0] = joints[:, 0]
    for j in topological_order()[1:]:
        p = PARENTS[j]
        v = joints[:, j] - joints[:, p]
        n = np.linalg.norm(v, axis=-1)
        ok = n > MIN_LENGTH
        d = np.where(ok[:, None], v / np.where(ok, n, 1.0)[:, None], 0.0)
        d = _fill_directions(d, ok, TPOSE_DIRECTIONS[j])
        out[:, j] = out[:, p] + lengths[j] * d
    return out


@node("filter.bone_length", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION}, params=BoneLengthParams)
def bone_length(ctx, motion):
    """Make every bone length constant (median over the clip, or given lengths), keeping bone directions."""
    joints, _ = motion_joints(motion)
    lengths = np.median(measure_bone_lengths(joints), axis=0)
    for name, value in ctx.params.lengths.items():
        lengths[JOINT_INDEX[name]] = value
    return {"motion": with_joints(motion, constant_bone_lengths(joints, lengths))}
