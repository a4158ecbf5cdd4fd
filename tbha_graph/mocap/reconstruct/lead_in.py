"""A T-pose lead-in for recorded motion: what an actor does at the start of a take, for tests and demos.

Real takes start with the actor in a T-pose facing the camera (the calibrators and the first frame of
``reconstruct.ray_sphere`` rely on it); motion-capture clips such as CMU's do not. :func:`tpose_lead_in`
prepends frames that hold a T-pose and then move smoothly into the clip's first frame, keeping every bone
length and the shoulder triangle rigid, so the result is a valid input for the whole pipeline.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import JOINT_INDEX, N_JOINTS, PARENTS, TPOSE_DIRECTIONS, TRIANGLE_JOINTS
from .ray_sphere import EXPANSION

_TRI = [JOINT_INDEX[j] for j in TRIANGLE_JOINTS]


def _slerp_dirs(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Unit vectors ``(m, 3)`` along the great circle from unit ``a`` to unit ``b`` at fractions ``s`` (m,)."""
    cos = float(np.clip(a @ b, -1.0, 1.0))
    theta = np.arccos(cos)
    if theta < 1e-9:
        return np.repeat(b[None], len(s), axis=0)
    if np.pi - theta < 1e-6:  # opposite: turn about any perpendicular axis
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        b_mid = perp / np.linalg.norm(perp)
        return np.where((s < 0.5)[:, None], _slerp_dirs(a, b_mid, 2 * s), _slerp_dirs(b_mid, b, 2 * s - 1))
    return (np.sin((1 - s) * theta)[:, None] * a + np.sin(s * theta)[:, None] * b) / np.sin(theta)


def tpose_lead_in(joints: np.ndarray, hold: int = 30, blend: int = 90) -> np.ndarray:
    """``(hold + blend + n, N_JOINTS, 3)`` metres: ``hold`` frames of T-pose, ``blend`` frames easing into
    ``joints[0]``, then ``joints`` ``(n, N_JOINTS, 3)`` (world frame, y up) unchanged.

    The T-pose keeps the clip's first-frame shoulder triangle (chest, shoulders), turned to face +z with the
    shoulders as near the body model's T-pose directions as its shape allows; it puts the neck straight up
    and the hips straight down from the chest, the limbs along
    :data:`~tbha_graph.mocap.skeleton.TPOSE_DIRECTIONS`, and stands at the first frame's chest position.
    All bone lengths and the triangle are those of the first frame.
    """
    from scipy.spatial.transform import Rotation, Slerp  # imported where it is used

    joints = np.asarray(joints, dtype=np.float64)
    first = joints[0]
    chest = JOINT_INDEX["chest"]
    tri = first[_TRI] - first[chest]
    lengths = np.linalg.norm(tri[1:], axis=1)
    model = TPOSE_DIRECTIONS[_TRI[1:]] * lengths[:, None]  # where the body model puts the shoulders
    # body -> world rotation of the first frame: turn the triangle's normal onto +z (so the T-pose triangle is
    # exactly coronal), then about z to best fit the shoulders onto the model's directions (2D Procrustes)
    normal = np.cross(tri[1], tri[2])  # (LS - chest) x (RS - chest): forward for a body facing +z
    to_z = Rotation.align_vectors([[0.0, 0.0, 1.0]], [normal])[0]
    flat = to_z.apply(tri[1:])
    angle = np.arctan2(np.sum(flat[:, 0] * model[:, 1] - flat[:, 1] * model[:, 0]), np.sum(flat[:, :2] * model[:, :2]))
    r_first = (Rotation.from_rotvec([0.0, 0.0, angle]) * to_z).inv()
    s = np.concatenate([np.zeros(hold), 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, blend + 1)[:-1])])
    rot = Slerp([0.0, 1.0], Rotation.concatenate([Rotation.identity(), r_first]))(s)
    m = len(s)
    lead = np.zeros((m, N_JOINTS, 3))
    lead[:, chest] = first[chest]
    body_tri = r_first.inv().apply(tri)
    for k, j in enumerate(_TRI):
        lead[:, j] = first[chest] + rot.apply(body_tri[k])
    for j, a in EXPANSION:
        vec = first[j] - first[a]
        length = np.linalg.norm(vec)
        if j == JOINT_INDEX["neck"]:
            rest = np.array([0.0, 1.0, 0.0])
        elif j == JOINT_INDEX["hips"]:
            rest = np.array([0.0, -1.0, 0.0])
        else:
            rest = TPOSE_DIRECTIONS[j] if PARENTS[j] == a else -TPOSE_DIRECTIONS[a]
        lead[:, j] = lead[:, a] + length * _slerp_dirs(rest / np.linalg.norm(rest), vec / length, s)
    return np.concatenate([lead, joints], axis=0)
