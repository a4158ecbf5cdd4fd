"""Steps shared by the rotation solvers: limb swings, the hinge refinement, local rotations, the bundle.

Conventions (BVH semantics, see :mod:`tbha_graph.mocap.ports`): ``world[j]`` is the rotation of joint
``j``'s frame from the rest pose; it orients the segment(s) from ``j`` to its children, so
``pos[c] = pos[j] + world[j] (offsets[c])``. ``local[j] = inv(world[parent]) * world[j]``. Quaternions
xyzw, arrays ``(n_frames, 16, 4)``; positions ``(n_frames, 16, 3)`` metres, world frame.

Joints with one child (neck, shoulders, elbows, hip joints, knees) get the shortest-arc swing from the
rest direction of that child's bone to its current direction (seed 002, no reference point); with
``swing_frame="parent"`` (default) the swing is taken in the parent's current frame, so a joint keeps
its parent's twist (the result does not depend on where the actor faces); ``"world"`` is the seed's
literal form (swing from the T-pose in world axes). Leaves (head, wrists, ankles) copy their parent's
orientation (local identity): nothing in 16 joints tells a hand's or foot's own rotation.

Hinge refinement (seed 002 axis limits, ``hinge=True``): the elbows and knees are hinges. The upper
segment (upper arm, thigh) has no twist information of its own; it takes the twist that makes the
hinge axis (fixed in its frame, :data:`.rest.HINGES`) perpendicular to the plane of the limb — the
seed's one-axis limit, with the forearm/shin as the neighbour that fixes the twist. The elbow/knee
rotation is then a pure rotation about that axis (the seed's two-axis limit) and positions are still
reproduced exactly. Flexion is positive; a bend against the hinge of at most ``max_hyperextension``
degrees is read as hyperextension (the twist stays near the default) rather than as a half-turned
upper arm. Nearly straight limbs say little about the bend plane: below ``straight`` degrees of bend
the twist correction fades out smoothly (so noise cannot spin the upper arm), and the elbow/knee
rotation may leave its axis by at most the (small) bend angle. ``hinge_projection=True`` instead
always keeps only the twist about the hinge axis (seed 1.3.2 literally): an exact hinge, at the cost of
the wrist/ankle missing its position by up to ``length * sin(bend)`` on nearly straight limbs.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ..kinematics import forward_kinematics
from ..skeleton import CHILDREN, JOINT_INDEX, N_JOINTS, PARENTS, TPOSE_DIRECTIONS, measure_bone_lengths
from ..quat import conj, continuous, dot, from_axis_angle, identity, quat_apply, quat_mul, shortest_arc, swing_twist, unit
from .reach import reach_feet
from .rest import HINGES, LEAVES, TORSO, TorsoReference, TorsoRest, end_offsets, rest_offsets

#: joints with exactly one child, grouped so that parents are solved before children
SWING_LEVELS: tuple[tuple[int, ...], ...] = (
    tuple(j for j in range(N_JOINTS) if len(CHILDREN[j]) == 1 and PARENTS[j] in TORSO),
    tuple(j for j in range(N_JOINTS) if len(CHILDREN[j]) == 1 and PARENTS[j] not in TORSO),
)
assert sorted(sum(SWING_LEVELS, ()) + tuple(TORSO) + LEAVES) == list(range(N_JOINTS))


class SolverParams(BaseModel):
    """Parameters common to the rotation solvers."""

    model_config = ConfigDict(extra="forbid")

    torso_rest: TorsoRest = Field(
        "measured", description="rest offsets of the torso joints' children: 'measured' (the actor's torso, median over the clip) or 'tpose'"
    )
    hips_reference: TorsoReference = Field(
        "spine", description="vector matched exactly by the hips rotation: 'spine' (to the chest) or 'triangle' (the hip-joint line)"
    )
    chest_reference: TorsoReference = Field(
        "triangle", description="vector matched exactly by the chest rotation: 'spine' (to the neck) or 'triangle' (the shoulder line)"
    )
    swing_frame: Literal["parent", "world"] = Field(
        "parent", description="single-child joints: shortest arc in the parent's frame, or from the T-pose in world axes (seed 002 literal)"
    )
    hinge: bool = Field(True, description="treat elbows and knees as hinges (upper arm/thigh twist from the limb plane)")
    hinge_projection: bool = Field(
        False, description="keep only the hinge-axis part of elbow/knee rotations even on straight limbs (exact hinge, inexact wrist/ankle)"
    )
    straight: float = Field(
        10.0, ge=0, le=90, description="bend below which a limb counts as nearly straight (twist correction fades out)", json_schema_extra={"unit": "deg"}
    )
    max_hyperextension: float = Field(
        10.0, ge=0, le=90, description="largest bend against the hinge read as hyperextension instead of a turned limb", json_schema_extra={"unit": "deg"}
    )
    end_length: float = Field(0.1, gt=0, le=1, description="End Site length of head and wrists", json_schema_extra={"unit": "m"})
    foot_length: float = Field(0.15, gt=0, le=1, description="End Site length of the ankles (a foot pointing forward)", json_schema_extra={"unit": "m"})
    torso_fit: bool = Field(
        True, description="refine the hips and chest rotations and the hips' position frame by frame (least squares) so "
                          "that all 16 joints land as close to the motion's as the rigid torso allows (rotations.torso_fit); "
                          "false: the reference vectors matched exactly and the others' miss carried by everything below them"
    )
    feet_reach: bool = Field(
        True, description="bend the knees so the ankles land on the motion's, from where the rigid pelvis puts the hip joints "
                          "(two-bone IK in the motion's knee plane: the feet stay where they were planted); false: thigh and shin "
                          "swung to the motion's directions, the feet moved by the pelvis's miss"
    )

    @property
    def references(self) -> dict[int, TorsoReference]:
        """Torso joint index -> its reference choice."""
        return {JOINT_INDEX["hips"]: self.hips_reference, JOINT_INDEX["chest"]: self.chest_reference}


def rest_skeleton(joints: np.ndarray, p: SolverParams) -> tuple[np.ndarray, np.ndarray]:
    """Median bone lengths ``(16,)`` and rest offsets ``(16, 3)`` metres for positions ``(n, 16, 3)``."""
    lengths = np.median(measure_bone_lengths(joints), axis=0)
    return lengths, rest_offsets(joints, lengths, p.torso_rest, p.references)


def rest_directions(offsets: np.ndarray) -> np.ndarray:
    """Unit rest bone directions ``(16, 3)``; zero-length bones fall back to the T-pose direction."""
    d, n = unit(offsets)
    return np.where((n > 0)[:, None], d, TPOSE_DIRECTIONS)


def solve_swings(world: np.ndarray, joints: np.ndarray, rest_dir: np.ndarray, p: SolverParams) -> None:
    """Fill ``world[:, j]`` ``(n, 16, 4)`` in place for the single-child joints (and, with ``p.hinge``,
    refine the hinge limbs) and the leaves, given ``world`` of ``hips`` and ``chest``."""
    hinge_upper = {h[0] for h in HINGES}
    hinge_mid = {h[1] for h in HINGES}
    for level in SWING_LEVELS:
        idx = np.array(level)
        child = np.array([CHILDREN[j][0] for j in level])
        cur = joints[:, child] - joints[:, idx]
        # hinge joints always swing in their (twisted) parent's frame: that is what makes them hinges
        in_parent = np.array([p.swing_frame == "parent" or (p.hinge and j in hinge_mid) for j in level])
        par = world[:, PARENTS[idx]]
        rel = quat_mul(par, shortest_arc(rest_dir[child], quat_apply(conj(par), cur)))
        if in_parent.all():
            world[:, idx] = rel
        else:
            world[:, idx] = np.where(in_parent[:, None], rel, shortest_arc(rest_dir[child], cur))
        if p.hinge and hinge_upper & set(level):
            _hinge_twist(world, joints, p)
    for j in LEAVES:
        world[:, j] = world[:, PARENTS[j]]


def pose_from_torso(torso_world: np.ndarray, joints: np.ndarray, offsets: np.ndarray, p: SolverParams) -> np.ndarray:
    """World rotations ``(n, 16, 4)``: ``torso_world``'s ``hips`` and ``chest`` kept, the other joints swung to the
    motion ``joints`` ``(n, 16, 3)`` (:func:`solve_swings`; the legs first re-placed to reach its ankles with
    ``p.feet_reach``, :func:`.reach.reach_feet`) for rest ``offsets`` ``(16, 3)``."""
    world = torso_world.copy()
    solve_swings(world, reach_feet(world, joints, offsets) if p.feet_reach else joints, rest_directions(offsets), p)
    return world


def posed_joints(world: np.ndarray, root: np.ndarray, offsets: np.ndarray, p: SolverParams) -> np.ndarray:
    """Positions ``(n, 16, 3)`` where the exported skeleton puts the joints: forward kinematics of world rotations
    ``world`` ``(n, 16, 4)`` (their local rotations, hinge-projected with ``p.hinge_projection``, as
    :func:`rotations_bundle` writes them) from the root positions ``root`` ``(n, 3)``."""
    local = local_from_world(world)
    if p.hinge and p.hinge_projection:
        local = project_hinges(local)
    return forward_kinematics(PARENTS, offsets, local, root)[0]


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _hinge_twist(world: np.ndarray, joints: np.ndarray, p: SolverParams) -> None:
    """Twist the upper segments of the hinge limbs about their own axis so the hinge axis is normal to
    the limb plane (see module doc); vectorised over frames and the four limbs."""
    upper = np.array([h[0] for h in HINGES])
    mid = np.array([h[1] for h in HINGES])
    end = np.array([h[2] for h in HINGES])
    axis = np.array([h[3] for h in HINGES])
    u, _ = unit(joints[:, mid] - joints[:, upper])  # (n, 4, 3)
    f, _ = unit(joints[:, end] - joints[:, mid])
    c = np.cross(u, f)
    sb = np.sqrt(dot(c, c))
    bend = np.arctan2(sb, dot(u, f))
    m, _ = unit(c)
    n_def = quat_apply(world[:, upper], axis)
    n_def = n_def - dot(n_def, u)[..., None] * u
    n_def, _ = unit(n_def)
    alpha = np.arctan2(dot(u, np.cross(n_def, m)), dot(n_def, m))
    hyper = (bend <= np.deg2rad(p.max_hyperextension)) & (np.abs(alpha) > np.pi / 2)
    alpha = np.where(hyper, alpha - np.copysign(np.pi, alpha), alpha)
    weight = _smoothstep(bend / np.deg2rad(p.straight)) if p.straight > 0 else (bend > 0).astype(float)
    alpha = np.where(sb > 1e-12, alpha * weight, 0.0)
    world[:, upper] = quat_mul(from_axis_angle(u, alpha), world[:, upper])


def local_from_world(world: np.ndarray) -> np.ndarray:
    """Local rotations ``(n, 16, 4)`` (relative to the parent; the root's is its world rotation)."""
    local = np.empty_like(world)
    local[:, 0] = world[:, 0]
    local[:, 1:] = quat_mul(conj(world[:, PARENTS[1:]]), world[:, 1:])
    return local


def project_hinges(local: np.ndarray) -> np.ndarray:
    """Keep only the hinge-axis twist of the elbow/knee local rotations ``(n, 16, 4)`` (seed 1.3.2)."""
    mid = np.array([h[1] for h in HINGES])
    axis = np.array([h[3] for h in HINGES])
    out = local.copy()
    out[:, mid] = swing_twist(local[:, mid], axis)[1]
    return out


def rotations_bundle(
    world: np.ndarray, joints: np.ndarray, offsets: np.ndarray, fps: float, p: SolverParams
) -> dict[str, np.ndarray]:
    """The ROTATIONS bundle from world rotations ``(n, 16, 4)`` and positions ``(n, 16, 3)``."""
    local = local_from_world(world)
    if p.hinge and p.hinge_projection:
        local = project_hinges(local)
    local = continuous(local / np.linalg.norm(local, axis=-1, keepdims=True))
    off = offsets.copy()
    off[0] = 0.0
    return {
        "local_quat": local,
        "root_position": joints[:, 0].copy(),
        "offsets": off,
        "end_offsets": end_offsets(off, p.end_length, p.foot_length),
        "fps": np.asarray(float(fps)),
    }


def empty_world(n: int) -> np.ndarray:
    """Identity world rotations ``(n, 16, 4)``."""
    return identity((n, N_JOINTS))
