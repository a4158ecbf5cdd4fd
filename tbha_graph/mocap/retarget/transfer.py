"""Transfer the 16-joint motion onto a character: world rotations for every character joint.

Inputs are a ROTATIONS bundle (identity = the capture's rest T-pose) and a :class:`.character.Character`.
All arrays are world axes (y up, facing +z), metres, quaternions xyzw, ``n`` frames, ``J`` character
joints. Per frame:

* a mapped joint ``t(j)`` gets world rotation ``W[j] * A[j]`` (``W``: the capture's world rotation of
  ``j``; ``A``: the rest alignment of :mod:`.alignment`), so its bones point where the capture's do;
* character joints strictly between two mapped joints of the spine or neck (Spine, Spine1 between
  Hips and Spine2) share the bend between them evenly (``between="distribute"``): with ``m`` joints
  from the upper mapped joint's first child to the lower mapped joint, the k-th takes world rotation
  ``G_p * B^(k/m)`` with ``B = G_p^-1 G_c`` (``G``: the mapped joints' world rotations), so a pose that
  puts the mapped joints at the character's rest leaves the whole spine at rest, and a difference
  between the two skeletons' rest spines is spread along the spine rather than kinked at one joint.
  With ``between="rest"`` they stay at rest and the whole bend sits at the lower mapped joint. Limb
  intermediates (a clavicle between chest and upper arm) and every other unmapped joint (fingers,
  toes, head tips) stay at rest relative to their parent; joints above the mapped hips (a "Root" at
  the floor) keep the identity;
* the mapped hips move along the capture's root trajectory scaled by ``scale`` = character hip-to-ankle
  height / capture hip-to-ankle height, so strides and the height of the pelvis follow the legs. With
  ``floor="clip"`` the height is measured from the capture's planted-ankle height (a low percentile,
  :data:`FLOOR_PERCENTILE`, of both ankles' heights over the clip) and lands at the character's own
  ankle height above its floor (rest ankle height above its lowest point, toe tips included), so the
  character's feet reach its floor y = 0 when the capture's reach theirs, whatever the proportions:
  ``y = scale * (y_capture - planted_capture) + planted_character``. ``floor="origin"`` scales the
  height about y = 0 like the other coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..kinematics import forward_kinematics
from ..quat import from_axis_angle, quat_inv, quat_mul, rotation_vector
from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, PARENTS
from .alignment import leg_height, rest_alignment, rest_positions16
from .character import Character

#: Percentile of the capture's ankle heights taken as its planted-ankle height (``floor="clip"``).
FLOOR_PERCENTILE = 5.0
#: 16-joint bones whose in-between character joints share the bend when ``between="distribute"``.
TORSO_CHAIN = (JOINT_INDEX["chest"], JOINT_INDEX["neck"], JOINT_INDEX["head"])


@dataclass
class Retargeted:
    """The motion on the character: ``local`` (n, J, 4) rotations relative to the parent, ``root`` (n, 3)
    position of the character's root joint, ``positions`` (n, J, 3) and ``world`` (n, J, 4) from forward
    kinematics; ``scale`` the root translation factor; ``distributed`` mapped joint -> character joints
    sharing its bend; ``at_rest`` unmapped character joints kept at rest relative to their parent;
    ``source_positions`` (n, 16, 3) the capture's joints (forward kinematics of the input);
    ``planted`` (capture, character) planted-ankle heights in metres (``None`` with ``floor="origin"``)."""

    local: np.ndarray
    root: np.ndarray
    positions: np.ndarray
    world: np.ndarray
    scale: float
    source_positions: np.ndarray
    distributed: dict[str, list[str]] = field(default_factory=dict)
    at_rest: list[str] = field(default_factory=list)
    planted: tuple[float, float] | None = None


def _power(q: np.ndarray, f: float) -> np.ndarray:
    """``q`` raised to the fraction ``f`` (same axis, ``f`` times the angle); ``(..., 4)``."""
    rv = rotation_vector(q)
    angle = np.linalg.norm(rv, axis=-1)
    axis = rv / np.where(angle > 1e-12, angle, 1.0)[..., None]
    return from_axis_angle(axis, f * angle)


def _roles(char: Character, between: str) -> tuple[dict[int, tuple[int, int, float]], list[int], set[int]]:
    """Which character joints share a bend: ``{joint: (mapped parent j16, mapped child c16, fraction)}``;
    also the joints above the mapped hips and the set of all joints lying between mapped joints."""
    shared: dict[int, tuple[int, int, float]] = {}
    inside: set[int] = set()
    limb_inside: set[int] = set()
    for c in range(1, N_JOINTS):
        p = int(PARENTS[c])
        chain = char.path_between(int(char.mapped[p]), int(char.mapped[c]))
        inside.update(chain)
        if between == "distribute" and c in TORSO_CHAIN:
            m = len(chain) + 1
            for k, u in enumerate(chain, start=1):
                shared[u] = (p, c, k / m)
        else:
            limb_inside.update(chain)
    for u in limb_inside:  # a joint also on a limb's path stays at rest (it carries the limb)
        shared.pop(u, None)
    above = char.ancestors(int(char.mapped[0]))
    return shared, above, inside


def character_planted_height(char: Character) -> float:
    """Rest height (metres) of the character's ankles above its lowest rest point (joints and End Sites)."""
    tips = (char.rest + char.ends)[np.asarray(char.end_mask, dtype=bool)]
    lowest = min(float(char.rest[:, 1].min()), float(tips[:, 1].min()) if tips.size else np.inf)
    ankles = char.mapped[[JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]]
    return float(char.rest[ankles, 1].mean()) - lowest


def retarget(rotations: dict[str, np.ndarray], char: Character, between: str = "distribute",
             floor: str = "clip") -> Retargeted:
    """Retarget a ROTATIONS bundle (``local_quat`` (n, 16, 4), ``root_position`` (n, 3), ``offsets``
    (16, 3), metres) onto ``char``; see the module docstring. ``between``: ``"distribute"`` or ``"rest"``;
    ``floor``: ``"clip"`` or ``"origin"``."""
    local16 = np.asarray(rotations["local_quat"], dtype=np.float64)
    root16 = np.asarray(rotations["root_position"], dtype=np.float64)
    offsets16 = np.asarray(rotations["offsets"], dtype=np.float64)
    n, nj = local16.shape[0], char.n_joints
    src_pos, src_world = forward_kinematics(PARENTS, offsets16, local16, root16)
    src_rest = rest_positions16(offsets16)
    tgt_rest = char.rest[char.mapped]
    align = rest_alignment(src_rest, tgt_rest)
    goal = quat_mul(src_world, align[None])  # (n, 16, 4) world rotation of each mapped character joint
    scale = leg_height(tgt_rest) / leg_height(src_rest)

    shared, above, _ = _roles(char, between)
    mapped_of = {int(t): j for j, t in enumerate(char.mapped)}
    world = np.tile([0.0, 0.0, 0.0, 1.0], (n, nj, 1))
    distributed: dict[str, list[str]] = {}
    at_rest: list[str] = []
    for t in range(nj):  # parents come before children in BVH order
        parent = int(char.parents[t])
        if t in mapped_of:
            world[:, t] = goal[:, mapped_of[t]]
        elif t in above:
            continue  # identity
        elif t in shared:
            p, c, f = shared[t]
            bend = quat_mul(quat_inv(goal[:, p]), goal[:, c])  # G_p^-1 G_c: identity when the character is at rest
            world[:, t] = quat_mul(goal[:, p], _power(bend, f))
            distributed.setdefault(JOINT_NAMES[c], []).append(char.names[t])
        else:
            world[:, t] = world[:, parent] if parent >= 0 else world[:, t]
            at_rest.append(char.names[t])
    parent_world = world[:, np.maximum(char.parents, 0)]
    local = quat_mul(quat_inv(parent_world), world)
    local[:, 0] = world[:, 0]

    hips = int(char.mapped[0])
    lift = char.rest[hips] - char.rest[0]  # rest offset root -> hips (ancestors never rotate)
    hips_path = scale * root16
    planted = None
    if floor == "clip":
        ankles = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
        planted = (float(np.percentile(src_pos[:, ankles, 1], FLOOR_PERCENTILE)), character_planted_height(char))
        hips_path[:, 1] = scale * (root16[:, 1] - planted[0]) + planted[1]
    root = hips_path - lift
    positions, world_fk = forward_kinematics(char.parents, char.offsets, local, root)
    return Retargeted(local, root, positions, world_fk, float(scale), src_pos, distributed, at_rest, planted)


def segment_direction_errors(ret: Retargeted, char: Character) -> dict[str, dict[str, float]]:
    """Per 16-joint bone (named by its child joint), the angle in degrees between the character's bone
    (mapped parent -> mapped child) and the capture's, over all frames: ``{"mean": .., "max": ..}``."""
    out = {}
    for c in range(1, N_JOINTS):
        p = int(PARENTS[c])
        a = ret.positions[:, char.mapped[c]] - ret.positions[:, char.mapped[p]]
        b = ret.source_positions[:, c] - ret.source_positions[:, p]
        cos = np.einsum("ni,ni->n", a, b) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        out[JOINT_NAMES[c]] = {"mean": float(ang.mean()), "max": float(ang.max())}
    return out
