"""``filter.foot_contact``: detect when each foot is planted and lock it there with two-bone leg IK.

All positions are metres, world frame, y up; ``joints`` (n, 16, 3); speeds m/s; ``fps`` frames/s.

1. **Floor**: the ankle height of a planted foot, estimated as a low percentile (``floor_percentile``)
   of both ankles' heights over the clip (the ankle joint sits a few cm above the ground).
2. **Contacts** (``mode: auto``): a foot is planted on frames where its ankle moves slower than
   ``max_speed`` (speed of the trajectory smoothed by a Gaussian of ``smooth_seconds``, so tracking
   noise does not hide a stance) and is less than ``max_height`` above the floor. Gaps shorter than
   ``max_gap_seconds`` are filled, then contacts shorter than ``min_contact_seconds`` dropped.
   ``always``: both feet planted for the whole clip; ``never``: nothing changed (contacts are still
   detected to report sliding); ``grounding``: no locking, the whole body is only moved vertically so
   that the lower ankle sits at the floor height (frames where both feet are higher than
   ``max_height`` above it, e.g. a hop, keep their height, with the shift interpolated across them).
3. **Lock**: during a contact the ankle is held at the median of its positions over that contact;
   over ``blend_seconds`` before and after, the target blends (smoothstep) from the motion's own ankle
   to the locked point, so the foot eases in and out.
4. **Two-bone IK** (hip joint - knee - ankle) moves the knee and ankle so the ankle reaches its
   target: both bone lengths of that frame are kept exactly; the knee stays in the plane through the
   hip, the new ankle and its original position (its original bend plane); a nearly straight leg
   bends forward (the pelvis's facing direction). An unreachable target is clamped to the reach of the
   leg (counted in the report). The hips and upper body are not moved (except by ``grounding``).

The ``report`` (JSON) holds foot sliding before and after, in mm per contact frame: the mean
horizontal displacement of an ankle between consecutive frames both in contact (the same detected
contacts are used for both figures), contact counts and fractions, the floor height, IK clamping.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node
from ..ports import MOTION, REPORT
from ..kinematics import two_bone_ik, unit_rows
from ..skeleton import JOINT_INDEX
from ..bundles.motion import motion_joints, with_joints

#: (hip joint, knee, ankle) indices of each leg
LEGS: dict[str, tuple[int, int, int]] = {
    side: (JOINT_INDEX[f"{side}_hip"], JOINT_INDEX[f"{side}_knee"], JOINT_INDEX[f"{side}_ankle"])
    for side in ("left", "right")
}


class FootContactParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    mode: Literal["auto", "always", "never", "grounding"] = Field(
        "auto", description="auto: detect contacts and lock feet; always: lock both feet all clip; never: change "
        "nothing (report only); grounding: only move the body so the lower foot is on the floor",
    )
    max_speed: float = Field(0.3, gt=0, description="a planted ankle moves slower than this (smoothed speed)",
                             json_schema_extra={"unit": "m/s"})
    max_height: float = Field(0.05, ge=0, description="a planted ankle is at most this far above the floor height",
                              json_schema_extra={"unit": "m"})
    floor_percentile: float = Field(5.0, ge=0, le=50, description="percentile of ankle heights taken as the floor "
                                    "(the ankle height of a planted foot)", json_schema_extra={"unit": "%"})
    smooth_seconds: float = Field(0.04, ge=0, le=1, description="Gaussian sigma smoothing the ankle trajectory "
                                  "before measuring its speed", json_schema_extra={"unit": "s"})
    min_contact_seconds: float = Field(0.1, ge=0, description="shorter contacts are ignored",
                                       json_schema_extra={"unit": "s"})
    max_gap_seconds: float = Field(0.05, ge=0, description="shorter breaks inside a contact are filled",
                                   json_schema_extra={"unit": "s"})
    blend_seconds: float = Field(0.1, ge=0, le=2, description="ease in / out of a lock over this long",
                                 json_schema_extra={"unit": "s"})


# ---------------------------------------------------------------------------------------------
# contact detection
# ---------------------------------------------------------------------------------------------
def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` frame ranges where the boolean ``mask`` (n,) is True."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def clean_contacts(mask: np.ndarray, min_frames: int, max_gap: int) -> np.ndarray:
    """Fill False gaps of at most ``max_gap`` frames between contacts, then drop contacts shorter than
    ``min_frames``; ``mask`` (n,) bool -> (n,) bool."""
    out = np.asarray(mask, dtype=bool).copy()
    n = out.size
    for a, b in runs(~out):
        if 0 < a and b < n and b - a <= max_gap:
            out[a:b] = True
    for a, b in runs(out):
        if b - a < min_frames:
            out[a:b] = False
    return out


def ankle_speed(ankle: np.ndarray, fps: float, smooth_seconds: float) -> np.ndarray:
    """Speed (n,) m/s of an ankle trajectory (n, 3) after Gaussian smoothing (sigma in seconds)."""
    from scipy.ndimage import gaussian_filter1d

    x = gaussian_filter1d(ankle, smooth_seconds * fps, axis=0, mode="nearest") if smooth_seconds > 0 else ankle
    if x.shape[0] < 2:
        return np.zeros(x.shape[0])
    return np.linalg.norm(np.gradient(x, axis=0), axis=-1) * fps


def floor_height(joints: np.ndarray, percentile: float) -> float:
    """Ankle height of a planted foot: the ``percentile`` of both ankles' heights, metres."""
    ankles = joints[:, [LEGS["left"][2], LEGS["right"][2]], 1]
    return float(np.percentile(ankles, percentile))


def detect_contacts(joints: np.ndarray, fps: float, p: FootContactParams, floor: float) -> dict[str, np.ndarray]:
    """Per foot a (n,) bool contact mask from ankle speed and height (see the module docstring)."""
    out = {}
    for side, (_, _, ankle) in LEGS.items():
        a = joints[:, ankle]
        raw = (ankle_speed(a, fps, p.smooth_seconds) < p.max_speed) & (a[:, 1] < floor + p.max_height)
        out[side] = clean_contacts(raw, int(round(p.min_contact_seconds * fps)), int(round(p.max_gap_seconds * fps)))
    return out


def sliding_mm(joints: np.ndarray, contacts: dict[str, np.ndarray]) -> tuple[float, int]:
    """Mean horizontal ankle displacement (mm) between consecutive frames both in contact, over both
    feet, and the number of such frame pairs (0 pairs gives 0.0)."""
    steps = []
    for side, (_, _, ankle) in LEGS.items():
        c = contacts[side]
        both = c[1:] & c[:-1]
        d = np.diff(joints[:, ankle][:, [0, 2]], axis=0)
        steps.append(np.linalg.norm(d[both], axis=-1))
    s = np.concatenate(steps)
    return (float(s.mean()) * 1000.0 if s.size else 0.0), int(s.size)


# ---------------------------------------------------------------------------------------------
# locking targets
# ---------------------------------------------------------------------------------------------
def lock_targets(ankle: np.ndarray, contact: np.ndarray, blend: int) -> tuple[np.ndarray, np.ndarray]:
    """Locked positions and blend weights of one ankle: ``target`` (n, 3), ``weight`` (n,) in [0, 1].

    Each contact holds the median of the ankle's positions over it (weight 1); ``blend`` frames on each
    side ease the weight with a smoothstep; where two contacts' ramps meet, the heavier one wins.
    """
    n = ankle.shape[0]
    target = ankle.copy()
    weight = np.zeros(n)
    frames = np.arange(n)
    for a, b in runs(contact):
        lock = np.median(ankle[a:b], axis=0)
        dist = np.maximum(np.maximum(a - frames, frames - (b - 1)), 0)  # frames outside the contact
        x = np.clip(1.0 - dist / (blend + 1.0), 0.0, 1.0)
        w = x * x * (3.0 - 2.0 * x)
        better = w > weight
        target[better] = lock
        weight[better] = w[better]
    return target, weight


# ---------------------------------------------------------------------------------------------
# locking the feet (two-bone IK: tbha_graph.mocap.kinematics.two_bone_ik)
# ---------------------------------------------------------------------------------------------
def facing(joints: np.ndarray) -> np.ndarray:
    """Unit facing direction (n, 3) of the pelvis: (left hip - right hip) x (chest - hips)."""
    lateral = joints[:, JOINT_INDEX["left_hip"]] - joints[:, JOINT_INDEX["right_hip"]]
    up = joints[:, JOINT_INDEX["chest"]] - joints[:, JOINT_INDEX["hips"]]
    return unit_rows(np.cross(lateral, up))


def lock_feet(joints: np.ndarray, contacts: dict[str, np.ndarray], blend: int) -> tuple[np.ndarray, dict]:
    """Joints (n, 16, 3) with each foot held during its contacts by two-bone IK; and IK statistics."""
    out = joints.copy()
    fwd = facing(joints)
    stats = {"ik_frames": 0, "ik_clamped_frames": 0, "ik_max_residual_mm": 0.0}
    for side, (hip, knee, ankle) in LEGS.items():
        target, weight = lock_targets(joints[:, ankle], contacts[side], blend)
        l1 = np.linalg.norm(joints[:, knee] - joints[:, hip], axis=-1)
        l2 = np.linalg.norm(joints[:, ankle] - joints[:, knee], axis=-1)
        f = np.flatnonzero((weight > 0) & (l1 > 1e-6) & (l2 > 1e-6))  # a collapsed leg cannot bend: left as is
        if f.size == 0:
            continue
        goal = (1.0 - weight[f, None]) * joints[f, ankle] + weight[f, None] * target[f]
        k, a, clamped = two_bone_ik(joints[f, hip], joints[f, knee], joints[f, ankle], goal, fwd[f])
        out[f, knee], out[f, ankle] = k, a
        stats["ik_frames"] += int(f.size)
        stats["ik_clamped_frames"] += int(clamped.sum())
        stats["ik_max_residual_mm"] = max(stats["ik_max_residual_mm"], float(np.linalg.norm(a - goal, axis=-1).max()) * 1000)
    return out, stats


def ground(joints: np.ndarray, floor: float, max_height: float) -> np.ndarray:
    """Shift every frame vertically so the lower ankle is at ``floor``; frames where both ankles are more
    than ``max_height`` above the floor take a shift interpolated from their grounded neighbours."""
    ankles = joints[:, [LEGS["left"][2], LEGS["right"][2]], 1].min(axis=1)
    shift = floor - ankles
    grounded = ankles < floor + max_height
    if grounded.any() and not grounded.all():
        frames = np.arange(joints.shape[0])
        shift = np.interp(frames, frames[grounded], shift[grounded])
    elif not grounded.any():
        shift = np.zeros_like(shift)
    out = joints.copy()
    out[..., 1] += shift[:, None]
    return out


@node("filter.foot_contact", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION, "report": REPORT},
      params=FootContactParams)
def foot_contact(ctx, motion):
    """Detect foot contacts (ankle speed and height) and lock planted feet with two-bone leg IK; report sliding."""
    p = ctx.params
    joints, fps = motion_joints(motion)
    n = joints.shape[0]
    floor = floor_height(joints, p.floor_percentile)
    contacts = detect_contacts(joints, fps, p, floor)
    if p.mode == "always":
        contacts = {side: np.ones(n, dtype=bool) for side in LEGS}
    stats: dict = {}
    if p.mode in ("auto", "always"):
        out, stats = lock_feet(joints, contacts, int(round(p.blend_seconds * fps)))
    elif p.mode == "grounding":
        out = ground(joints, floor, p.max_height)
    else:
        out = joints
    before, pairs = sliding_mm(joints, contacts)
    after, _ = sliding_mm(out, contacts)
    report = {
        "mode": p.mode,
        "frames": n,
        "floor_ankle_height_m": floor,
        "contact_frames": {side: int(c.sum()) for side, c in contacts.items()},
        "contacts": {side: len(runs(c)) for side, c in contacts.items()},
        "contact_fraction": {side: float(c.mean()) for side, c in contacts.items()},
        "foot_sliding_before_mm": before,
        "foot_sliding_after_mm": after,
        "foot_sliding_frame_pairs": pairs,
        **stats,
    }
    ctx.log(f"foot sliding {before:.2f} -> {after:.2f} mm per contact frame ({pairs} frame pairs)")
    return {"motion": with_joints(motion, out), "report": report}
