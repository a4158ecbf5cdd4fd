"""``filter.fill_gaps``: fill joints lost to occlusion, and flag every filled sample as inferred.

Two fills, in order, on joints whose ``tracked`` flag is False:

1. **Rigid-body fill** for the torso, in two nearly rigid groups (chest-neck-shoulders; pelvis-hip
   joints-chest): when at least 3 other joints of a group are tracked in the frame, the missing one is
   placed by the rigid transform (Kabsch) that maps the group in the nearest frame (in time) where it
   is fully tracked onto the tracked ones (the nearest frame, because the shoulders shrug).
2. **Interpolation** (shape-preserving cubic, PCHIP) across interior gaps of at most ``max_gap_frames``.

Longer gaps and gaps at the start or end of the take are **left missing and flagged**, not invented:
their positions stay what the solver predicted, ``tracked`` stays False and ``inferred`` stays False;
``report["long_gaps"]`` lists them as ``[joint, first, last]`` (rows, ``last`` included) and
``evaluate.metrics`` reports their frames in ``doubtful_ranges`` (reason ``unfilled gap``). Output MOTION
gains ``inferred`` ``(n_frames, 16)`` bool; ``report`` counts filled and missing samples per joint.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import MOTION, report_port
from ..rigid import procrustes
from ..skeleton import JOINT_INDEX, JOINT_NAMES
from ..bundles.motion import motion_joints, with_joints

#: Nearly rigid groups: the upper torso (shoulder girdle) and the pelvis with the chest (the spine bends
#: between them, so one rigid body for the whole torso would be centimetres off at the shoulders).
RIGID_GROUPS = (
    tuple(JOINT_INDEX[n] for n in ("chest", "neck", "left_shoulder", "right_shoulder")),
    tuple(JOINT_INDEX[n] for n in ("hips", "left_hip", "right_hip", "chest")),
)


class FillGapsParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    max_gap_frames: int = Field(15, ge=1, description="longest gap bridged by interpolation", json_schema_extra={"unit": "frame"})
    rigid_torso: bool = Field(True, description="fill torso joints from the other tracked torso joints (rigid body)")


def rigid_torso_fill(joints: np.ndarray, tracked: np.ndarray) -> np.ndarray:
    """Boolean ``(n, 16)`` of the torso samples filled in place in ``joints`` (see module doc)."""
    filled = np.zeros_like(tracked)
    for group in RIGID_GROUPS:
        filled |= rigid_group_fill(joints, tracked | filled, np.array(group))
    return filled


def rigid_group_fill(joints: np.ndarray, tracked: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Fill missing members of one rigid group ``idx`` in place; boolean ``(n, 16)`` of filled samples."""
    filled = np.zeros_like(tracked)
    t = tracked[:, idx]
    full = t.all(axis=1)
    if not full.any():
        return filled
    need = (~t).any(axis=1) & (t.sum(axis=1) >= 3)
    if not need.any():
        return filled
    frames = np.flatnonzero(need)
    full_frames = np.flatnonzero(full)
    pos = np.clip(np.searchsorted(full_frames, frames), 1, max(len(full_frames) - 1, 1))
    before = full_frames[np.clip(pos - 1, 0, len(full_frames) - 1)]
    after = full_frames[np.clip(pos, 0, len(full_frames) - 1)]
    nearest = np.where(np.abs(frames - before) <= np.abs(after - frames), before, after)
    src = joints[nearest][:, idx]
    dst = joints[frames][:, idx]
    _, R, tr = procrustes(src, dst, t[frames].astype(float))  # dst ~ R src + tr
    placed = np.einsum("nij,nkj->nki", R, src) + tr[:, None, :]
    miss = ~t[frames]
    sub = joints[frames][:, idx]
    sub[miss] = placed[miss]
    joints[frames[:, None], idx[None, :]] = sub
    filled[frames[:, None], idx[None, :]] = miss
    return filled


def interpolate_gaps(joints: np.ndarray, known: np.ndarray, max_gap: int) -> np.ndarray:
    """Fill interior runs of ``~known`` no longer than ``max_gap`` by PCHIP per joint, in place; returns
    the boolean ``(n, 16)`` of filled samples."""
    from scipy.interpolate import PchipInterpolator

    n = joints.shape[0]
    filled = np.zeros_like(known)
    frames = np.arange(n)
    for j in range(joints.shape[1]):
        k = known[:, j]
        if k.all() or k.sum() < 2:
            continue
        # runs of missing samples: start/end indices
        edges = np.diff(np.concatenate([[0], (~k).astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        ok = (starts > 0) & (ends < n) & (ends - starts <= max_gap)
        if not ok.any():
            continue
        f = PchipInterpolator(frames[k], joints[k, j], axis=0)
        for s, e in zip(starts[ok], ends[ok]):
            joints[s:e, j] = f(frames[s:e])
            filled[s:e, j] = True
    return filled


def missing_runs(missing: np.ndarray) -> list[list]:
    """``[[joint name, first, last], ...]``: the runs of ``missing`` (n, 16) per joint, by first frame."""
    out = []
    for j in range(missing.shape[1]):
        edges = np.diff(np.concatenate([[0], missing[:, j].astype(np.int8), [0]]))
        for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            out.append([JOINT_NAMES[j], int(s), int(e - 1)])
    return sorted(out, key=lambda r: (r[1], r[2], r[0]))


@node(
    "filter.fill_gaps",
    version=1,
    inputs={"motion": MOTION},
    outputs={"motion": MOTION, "report": report_port("filled and still-missing samples per joint")},
    params=FillGapsParams,
)
def fill_gaps(ctx, motion):
    """Fill joints lost to occlusion (rigid torso, then spline across short gaps); flag them as inferred."""
    joints, _ = motion_joints(motion)
    joints = joints.copy()
    tracked = np.asarray(motion.get("tracked", np.ones(joints.shape[:2], bool)), dtype=bool)
    inferred = np.zeros_like(tracked)
    if ctx.params.rigid_torso:
        inferred |= rigid_torso_fill(joints, tracked)
    inferred |= interpolate_gaps(joints, tracked | inferred, ctx.params.max_gap_frames)
    missing = ~(tracked | inferred)
    out = with_joints(motion, joints)
    out["tracked"] = tracked
    out["inferred"] = inferred
    report = {
        "inferred_samples": int(inferred.sum()),
        "missing_samples": int(missing.sum()),
        "inferred_pct": round(100.0 * float(inferred.mean()), 3),
        "per_joint_inferred": {JOINT_NAMES[j]: int(inferred[:, j].sum()) for j in range(len(JOINT_NAMES)) if inferred[:, j].any()},
        "per_joint_missing": {JOINT_NAMES[j]: int(missing[:, j].sum()) for j in range(len(JOINT_NAMES)) if missing[:, j].any()},
        "long_gaps": missing_runs(missing),
    }
    if report["long_gaps"]:
        ctx.log(f"{len(report['long_gaps'])} gap(s) longer than {ctx.params.max_gap_frames} frames (or at the take's "
                f"ends) left unfilled and flagged, e.g. {report['long_gaps'][0]}")
    return {"motion": out, "report": report}
