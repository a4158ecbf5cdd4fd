"""The rigid torso fitted by least squares: every joint as close to the motion's as a 16-joint skeleton allows.

A 16-joint skeleton has one rigid segment for the pelvis (``hips`` with ``chest``, ``left_hip``, ``right_hip``) and
one for the thorax (``chest`` with ``neck`` and the shoulders); a real torso bends (a lumbar spine, a neck), and a
solver's torso is held near-rigid only softly. The seed's reference-point rotations (:mod:`.quaternion`) or a
Kabsch fit of the three children (:mod:`.kabsch`) match some torso joints exactly and leave the others' miss to
move everything below them: on the bundled sample the solver's hip joints came out 27 mm off in the BVH, the neck
25 mm, the exported joints 50.6 mm from the truth against the solver's 47.7 (47.8 with this fit).

Here, per frame, nine unknowns — a shift of the hips' position (metres) and a correction rotation of ``hips`` and
of ``chest`` (rotation vectors, radians, applied before their rotation from the solver) — are fitted by
Levenberg–Marquardt to minimise the sum over all 16 joints of the squared distance between where the skeleton then
puts them (the limbs swung and the legs reaching as :func:`.common.pose_from_torso` does) and the motion's. Frames
are independent small problems: solved together, one vectorised pass per iteration (finite-difference Jacobians
of all frames from one batch of ten posings; ``scipy.optimize.least_squares`` finds the same optimum with a
block-sparse Jacobian, about ten times slower). Each frame starts at the reference rotations (no correction), so
motion the skeleton can take exactly stays exact, and a step is kept only where it lowers that frame's cost.

Positions ``(n, 16, 3)`` metres, world frame; rotations xyzw ``(n, 16, 4)``.
"""
from __future__ import annotations

import numpy as np

from ..quat import from_axis_angle, quat_mul
from .common import SolverParams, pose_from_torso, posed_joints

#: unknowns per frame: hips shift (3), hips correction (3), chest correction (3)
N_UNKNOWNS = 9
#: frames fitted at once (each is its own problem): bounds the memory of the Jacobians' batch of ten posings
CHUNK = 1024


def rotation_quat(rotvec: np.ndarray) -> np.ndarray:
    """Quaternions xyzw ``(..., 4)`` of rotation vectors ``(..., 3)`` (radians; zero: the identity)."""
    angle = np.sqrt(np.einsum("...i,...i->...", rotvec, rotvec))
    return from_axis_angle(rotvec / np.where(angle > 0, angle, 1.0)[..., None], angle)


def corrected(x: np.ndarray, torso_world: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(n, 16, 4)`` with ``hips``/``chest`` corrected by ``x`` ``(n, 9)`` (see module doc) and the
    motion ``joints`` ``(n, 16, 3)`` with its hips moved by the shift (the root the skeleton hangs from)."""
    world = torso_world.copy()
    world[:, 0] = quat_mul(rotation_quat(x[:, 3:6]), torso_world[:, 0])
    world[:, 1] = quat_mul(rotation_quat(x[:, 6:9]), torso_world[:, 1])
    moved = joints.copy()
    moved[:, 0] += x[:, :3]
    return world, moved


def misses(x: np.ndarray, torso_world: np.ndarray, joints: np.ndarray, offsets: np.ndarray, p: SolverParams) -> np.ndarray:
    """Per frame, where the skeleton puts every joint minus where the motion has it, ``(n, 48)`` metres."""
    world, moved = corrected(x, torso_world, joints)
    posed = posed_joints(pose_from_torso(world, moved, offsets, p), moved[:, 0], offsets, p)
    return (posed - joints).reshape(joints.shape[0], -1)


def fit_torso(torso_world: np.ndarray, joints: np.ndarray, offsets: np.ndarray, p: SolverParams,
              iterations: int = 6, step: float = 1e-6, tol: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """``(torso_world, joints)`` refined (module doc): world rotations ``(n, 16, 4)`` whose ``hips`` and ``chest``
    are corrected, and the motion's joints ``(n, 16, 3)`` with the hips moved to where the skeleton's root goes.
    ``offsets`` ``(16, 3)`` the rest skeleton; ``iterations`` Jacobians at most; ``step`` the finite difference
    (metres and radians); each frame stops when its cost falls by less than ``tol`` of itself. Frames are fitted
    :data:`CHUNK` at a time, so memory stays flat however long the take."""
    x = np.zeros((joints.shape[0], N_UNKNOWNS))
    for a in range(0, joints.shape[0], CHUNK):
        rows = slice(a, a + CHUNK)
        x[rows] = fitted_unknowns(torso_world[rows], joints[rows], offsets, p, iterations, step, tol)
    return corrected(x, torso_world, joints)


def fitted_unknowns(torso_world: np.ndarray, joints: np.ndarray, offsets: np.ndarray, p: SolverParams,
                    iterations: int, step: float, tol: float) -> np.ndarray:
    """The nine unknowns ``(n, 9)`` of every frame (module doc) by Levenberg–Marquardt (see :func:`fit_torso`). Each
    frame iterates until its own cost stops falling (by ``tol`` of itself), so its answer does not depend on which
    other frames are fitted with it."""
    n = joints.shape[0]
    x = np.zeros((n, N_UNKNOWNS))
    probes = np.concatenate([np.zeros((1, N_UNKNOWNS)), step * np.eye(N_UNKNOWNS)])  # (10, 9)
    r = misses(x, torso_world, joints, offsets, p)
    cost = np.einsum("ij,ij->i", r, r)
    damping = np.full(n, 1e-3)
    eye = np.eye(N_UNKNOWNS)
    active = np.arange(n)  # frames still iterating
    for _ in range(iterations):
        if active.size == 0:
            break
        world, target = torso_world[active], joints[active]
        batch = (x[active][None] + probes[:, None]).reshape(-1, N_UNKNOWNS)
        R = misses(batch, np.concatenate([world] * len(probes)), np.concatenate([target] * len(probes)), offsets,
                   p).reshape(len(probes), active.size, -1)
        jac = np.moveaxis((R[1:] - R[:1]) / step, 0, -1)  # (k, 48, 9)
        jt = np.swapaxes(jac, 1, 2)
        A = jt @ jac
        g = (jt @ r[active][..., None])[..., 0]
        gain = np.zeros(active.size)
        todo = np.arange(active.size)  # frames (of active) still looking for a step from this linearisation
        for _ in range(4):  # damping raised where a step fails, lowered where it succeeds
            f = active[todo]
            D = A[todo] + damping[f, None, None] * (eye * np.diagonal(A[todo], axis1=1, axis2=2)[:, None, :]) + 1e-12 * eye
            dx = -np.linalg.solve(D, g[todo][..., None])[..., 0]
            r_new = misses(x[f] + dx, world[todo], target[todo], offsets, p)
            c_new = np.einsum("ij,ij->i", r_new, r_new)
            ok = c_new < cost[f]  # NaN never passes
            good = f[ok]
            gain[todo[ok]] = (cost[good] - c_new[ok]) / np.maximum(cost[good], 1e-30)
            x[good] += dx[ok]
            r[good] = r_new[ok]
            cost[good] = c_new[ok]
            damping[good] *= 0.3
            damping[f[~ok]] *= 10.0
            todo = todo[~ok]
            if todo.size == 0:
                break
        active = active[gain >= tol]
    return x
