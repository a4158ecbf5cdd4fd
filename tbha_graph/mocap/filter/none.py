"""``filter.none``: the identity filter, so a study can compare filters against no filtering."""
from __future__ import annotations

from ..ports import MOTION
from ..bundles.motion import motion_joints, with_joints
from ...core.node import node


@node("filter.none", version=1, inputs={"motion": MOTION}, outputs={"motion": MOTION})
def none(ctx, motion):
    """Pass the motion through unchanged (joints checked for NaN like every filter)."""
    joints, _ = motion_joints(motion)
    return {"motion": with_joints(motion, joints)}
