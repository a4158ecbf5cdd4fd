"""Node ``synth.tpose_lead_in``: a BVH clip that starts the way a real capture starts.

The actor first stands in a T-pose facing the camera (+z) for ``hold_seconds``, then blends into the
clip over ``blend_seconds`` while the clip plays, then the clip continues. The calibration and the
first-frame labelling rely on that opening pose.

How (on the *source* skeleton, so bone lengths never change):

1. The source rest pose is turned into a T-pose: the CMU rest pose is **not** one (its arms hang down
   and its legs splay outwards), so each limb's rotating joint (shoulder, elbow, hip, knee as mapped)
   gets the shortest-arc rotation that points its bone along the 16-joint T-pose direction (arms along
   +-x, legs down). The spine and feet keep their rest shape.
2. The clip is turned about the vertical so that the actor faces +z at its first frame (facing = hips'
   and shoulders' left-right line x up), and moved so its root starts above the origin.
3. Every joint's local rotation is slerped from the T-pose to the clip (root rotation included), with a
   smoothstep weight; the root position is interpolated linearly; forward kinematics on the source
   skeleton; then the mapped 16 joints, in metres.
4. Optional extra turn (``turn_degrees``): from ``turn_start`` over ``turn_seconds`` the clip's heading
   is turned progressively (smoothstep) about the vertical; each frame's root displacement is turned
   with it, so a straight walk becomes a walk along a curve that turns round (bone lengths unchanged).
5. Height: the clip is shifted vertically so that, standing, the ankle joint centres are
   ``ankle_height`` above the floor (y = 0; 5th percentile of the lower ankle over the clip), and the
   T-pose stands with its lower ankle at that height too.

Output ``motion`` (MOTION): ``joints`` (n, 16, 3) metres world, ``fps`` (the BVH's), ``joint_names``.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..kinematics import forward_kinematics
from ..quat import quat_inv, quat_mul
from ..ports import MOTION
from ..skeleton import JOINT_INDEX, JOINT_NAMES, TPOSE_DIRECTIONS

#: The 16-joint bones a T-pose sets (parent joint rotates, child joint gives the direction).
LIMB_BONES: tuple[tuple[str, str], ...] = tuple(
    (f"{side}_{a}", f"{side}_{b}")
    for side in ("left", "right")
    for a, b in (("shoulder", "elbow"), ("elbow", "wrist"), ("hip", "knee"), ("knee", "ankle"))
)


class LeadInParams(BaseModel):
    """Which clip, and how the T-pose opening is timed."""

    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="BVH file of the motion")
    mapping: str = Field("cmu", description="skeleton mapping (bundled name or YAML path) onto the 16 joints")
    hold_seconds: float = Field(1.0, ge=0, le=60, description="time standing in the T-pose", json_schema_extra={"unit": "s"})
    blend_seconds: float = Field(0.5, ge=0, le=30, description="time blending from the T-pose into the clip", json_schema_extra={"unit": "s"})
    start: float = Field(0.0, ge=0, description="start of the clip part used", json_schema_extra={"unit": "s"})
    duration: float | None = Field(None, gt=0, description="length of the clip part used (None: to the end)", json_schema_extra={"unit": "s"})
    ankle_height: float = Field(0.08, gt=0, le=0.3, description="ankle joint centre above the floor when standing", json_schema_extra={"unit": "m"})
    turn_degrees: float = Field(
        0.0, ge=-1080, le=1080,
        description="extra heading change given to the clip (about the vertical, + = to the actor's left): the "
                    "root's rotation and its walking direction turn together, so a straight walk becomes a walk "
                    "that turns round", json_schema_extra={"unit": "deg"},
    )
    turn_start: float = Field(0.0, ge=0, description="clip time at which the extra turn starts", json_schema_extra={"unit": "s"})
    turn_seconds: float = Field(2.0, gt=0, le=60, description="time the extra turn takes (smoothstep)", json_schema_extra={"unit": "s"})


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Slerp (..., 4) xyzw quaternions from q0 to q1 by weights w (...,) (shortest arc)."""
    from scipy.spatial.transform import Rotation

    shape = q1.shape
    q0 = np.broadcast_to(q0, shape).reshape(-1, 4)
    r0 = Rotation.from_quat(q0)
    rel = (r0.inv() * Rotation.from_quat(q1.reshape(-1, 4))).as_rotvec()
    ww = np.broadcast_to(np.asarray(w, dtype=np.float64), shape[:-1]).reshape(-1, 1)
    return (r0 * Rotation.from_rotvec(rel * ww)).as_quat().reshape(shape)


def tpose_rotations(parents: np.ndarray, offsets: np.ndarray, idx16: np.ndarray, world_from_source: np.ndarray) -> np.ndarray:
    """Local rotations (J, 4) xyzw of the source skeleton that put it in the 16-joint T-pose.

    ``idx16`` (16,) source joint of each TBHA joint; ``world_from_source`` (3, 3) axes map. Each limb bone
    of :data:`LIMB_BONES` is turned (shortest arc, at its parent's source joint) to
    :data:`tbha_graph.mocap.skeleton.TPOSE_DIRECTIONS`; other joints keep their rest rotation (identity).
    """
    from scipy.spatial.transform import Rotation

    J = len(parents)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (1, J, 1))
    for pname, cname in LIMB_BONES:
        sp, sc = int(idx16[JOINT_INDEX[pname]]), int(idx16[JOINT_INDEX[cname]])
        pos, world = forward_kinematics(parents, offsets, q, np.zeros((1, 3)))
        cur = pos[0, sc] - pos[0, sp]
        want = world_from_source.T @ TPOSE_DIRECTIONS[JOINT_INDEX[cname]]
        if np.linalg.norm(cur) < 1e-9:
            continue
        delta = Rotation.align_vectors(want[None], cur[None])[0].as_quat()
        w_new = quat_mul(delta, world[0, sp])
        par = parents[sp]
        q[0, sp] = w_new if par < 0 else quat_mul(quat_inv(world[0, par]), w_new)
    return q[0]


def _facing_angle(joints16: np.ndarray) -> float:
    """Heading (radians about +y, 0 = facing +z) of a 16-joint pose (16, 3) world."""
    j = joints16
    left = (j[JOINT_INDEX["left_hip"]] - j[JOINT_INDEX["right_hip"]]) + (
        j[JOINT_INDEX["left_shoulder"]] - j[JOINT_INDEX["right_shoulder"]]
    )
    front = np.cross(left, [0.0, 1.0, 0.0])
    return float(np.arctan2(front[0], front[2]))


def _turn_clip(local: np.ndarray, root: np.ndarray, A: np.ndarray, fps: float, p: LeadInParams):
    """The clip with the extra heading change of ``p.turn_degrees`` (module docstring, step 4)."""
    from scipy.spatial.transform import Rotation

    t = np.arange(local.shape[0]) / fps
    x = np.clip((t - p.turn_start) / p.turn_seconds, 0.0, 1.0)
    angle = np.radians(p.turn_degrees) * x * x * (3.0 - 2.0 * x)
    turn = Rotation.from_matrix(A.T @ Rotation.from_rotvec(angle[:, None] * [0.0, 1.0, 0.0]).as_matrix() @ A)
    step = np.diff(root, axis=0)
    root = np.concatenate([root[:1], root[:1] + np.cumsum(turn[1:].apply(step), axis=0)])
    local = local.copy()
    local[:, 0] = (turn * Rotation.from_quat(local[:, 0])).as_quat()
    return local, root


def lead_in_motion(p: LeadInParams) -> tuple[np.ndarray, float]:
    """Joints (n, 16, 3) metres world and fps of the clip with its T-pose opening (module docstring)."""
    from scipy.spatial.transform import Rotation

    from ..io.bvh import bvh_to_local, read_bvh
    from ..io.skeleton_map import joint_indices, load_mapping

    m = load_mapping(p.mapping)
    bvh = read_bvh(p.path)
    idx = joint_indices(bvh, m, str(p.path))
    if any(c.endswith("position") for j in bvh.joints[1:] for c in j.channels):
        raise NodeError(
            f"{p.path}: joints other than the root have position channels; the T-pose lead-in needs fixed bone lengths",
            hint="use a BVH whose only position channels are the root's",
        )
    fps = float(bvh.fps)
    A = m.world_from_source()
    scale = float(m.units_to_metres)
    n_src = bvh.n_frames
    i0 = int(round(p.start * fps))
    if i0 >= n_src:
        raise NodeError(
            f"start {p.start} s is past the end of {p.path} ({n_src} frames = {(n_src - 1) / fps:.2f} s)",
            hint="choose a smaller start",
        )
    i1 = n_src if p.duration is None else min(n_src, i0 + int(round(p.duration * fps)) + 1)
    local, root = bvh_to_local(bvh)
    local, root = local[i0:i1].copy(), root[i0:i1].copy()
    parents, offsets = bvh.parents, bvh.offsets

    def joints16(lq: np.ndarray, rp: np.ndarray) -> np.ndarray:
        pos = forward_kinematics(parents, offsets, lq, rp)[0][:, idx]
        return (pos @ A.T) * scale

    # face +z at the first frame, root above the origin
    first = joints16(local[:1], root[:1])[0]
    heading = Rotation.from_rotvec([0.0, -_facing_angle(first), 0.0])
    h_src = Rotation.from_matrix(A.T @ heading.as_matrix() @ A)
    r0w = A @ root[0] * scale
    root = h_src.apply(root - A.T @ np.array([r0w[0], 0.0, r0w[2]]) / scale)
    local[:, 0] = (h_src * Rotation.from_quat(local[:, 0])).as_quat()

    if p.turn_degrees:
        local, root = _turn_clip(local, root, A, fps, p)

    # floor: standing ankles at ankle_height
    ank = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    clip = joints16(local, root)
    shift = p.ankle_height - float(np.percentile(clip[:, ank, 1].min(axis=1), 5))
    root = root + A.T @ np.array([0.0, shift, 0.0]) / scale
    q_t = tpose_rotations(parents, offsets, idx, A)
    tpose = joints16(q_t[None], np.zeros((1, 3)))[0]
    root_t = A.T @ np.array([0.0, p.ankle_height - tpose[ank, 1].min(), 0.0]) / scale

    n_clip = local.shape[0]
    n_hold = int(round(p.hold_seconds * fps))
    n_blend = min(int(round(p.blend_seconds * fps)), n_clip)
    k = np.arange(n_hold + n_clip)
    ci = np.maximum(k - n_hold, 0)
    x = np.clip((k - n_hold + 1) / (n_blend + 1), 0.0, 1.0) if n_blend > 0 else (k >= n_hold).astype(float)
    w = x * x * (3.0 - 2.0 * x)  # smoothstep: no jerk at either end of the blend
    lq = _slerp(q_t[None], local[ci], w[:, None])
    rp = (1.0 - w)[:, None] * root_t + w[:, None] * root[ci]
    return joints16(lq, rp), fps


@node("synth.tpose_lead_in", version=1, outputs={"motion": MOTION}, params=LeadInParams)
def tpose_lead_in(ctx):
    """A BVH clip opened by a T-pose facing the camera (+z) that blends smoothly into the motion."""
    joints, fps = lead_in_motion(ctx.params)
    return {"motion": {"joints": joints, "fps": np.array(fps), "joint_names": np.array(JOINT_NAMES)}}
