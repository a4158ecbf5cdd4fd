"""Quaternions: the project's one module of quaternion and rotation-vector math (numpy only).

Quaternions are stored in scipy's scalar-last order ``(x, y, z, w)`` as float64 arrays of shape
``(..., 4)``; every function broadcasts over the leading axes (frames, joints). Rotations act on column
vectors (``q`` applied to ``v`` is ``R(q) @ v``) and ``quat_mul(a, b)`` is the rotation "first ``b``,
then ``a``", i.e. ``R(a) @ R(b)``, matching ``scipy.spatial.transform.Rotation`` (``Ra * Rb``). Plain
numpy arithmetic is several times faster than building scipy ``Rotation`` objects for small batches.

* :func:`quat_mul`, :func:`quat_inv`, :func:`conj`, :func:`quat_apply`, :func:`quat_to_matrix`,
  :func:`quat_normalize`, :func:`identity`, :func:`from_axis_angle`, :func:`rotation_vector`,
  :func:`angle_of`: arithmetic and conversions.

The rotation solvers' constructions (seed 002) never return NaN: zero-length vectors, parallel /
anti-parallel pairs and collinear reference points fall back to a documented choice instead.

* :func:`shortest_arc` — seed 002 "no reference point": the smallest rotation taking ``a`` to ``b``.
* :func:`rotation_from_pairs` — seed 002 "with reference points": the rotation taking ``u1 -> v1``
  and ``u2 -> v2``, its axis the intersection of the two perpendicular-bisector planes.
* :func:`swing_twist` — split a rotation into a twist about an axis and the remaining swing
  (the seed's axis-limit refinement keeps or removes the twist part).
"""
from __future__ import annotations

import numpy as np


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` xyzw; broadcasts; returns ``(..., 4)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ),
        axis=-1,
    )


def quat_inv(q: np.ndarray) -> np.ndarray:
    """Inverse of quaternions ``(..., 4)`` xyzw (conjugate divided by the squared norm)."""
    q = np.asarray(q, dtype=np.float64)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return conj / np.sum(q * q, axis=-1, keepdims=True)


def quat_apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` ``(..., 3)`` by unit quaternions ``q`` ``(..., 4)`` xyzw; broadcasts.

    Uses ``v' = v + 2w (u x v) + 2 u x (u x v)`` with ``u`` the vector part (no matrices built).
    """
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` xyzw."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack(
        (
            1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
            2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
            2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
        ),
        axis=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` scaled to unit norm."""
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)



#: vectors shorter than this are treated as zero (metres or unit-free, inputs are O(1))
EPS = 1e-12
#: ``1 + cos(angle)`` below this counts as anti-parallel (angle within ~1e-4 degrees of 180)
_ANTI = 1e-12
#: unit-vector cross products shorter than this count as parallel
_PARALLEL = 1e-9


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis, ``(..., k) x (..., k) -> (...)`` (broadcasting)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    return np.einsum("...i,...i->...", a, b)


def conj(q: np.ndarray) -> np.ndarray:
    """Conjugate ``(-x, -y, -z, w)``: the inverse of a unit quaternion ``(..., 4)``."""
    return np.asarray(q, dtype=np.float64) * _CONJ


_CONJ = np.array([-1.0, -1.0, -1.0, 1.0])


def unit(v: np.ndarray, eps: float = EPS) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors of ``v`` ``(..., 3)`` and their norms ``(...)``; vectors shorter than ``eps`` map to 0."""
    v = np.asarray(v, dtype=np.float64)
    n = np.sqrt(dot(v, v))
    ok = n > eps
    safe = np.where(ok, n, 1.0)[..., None]
    return np.where(ok[..., None], v / safe, 0.0), n


def perpendicular(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each ``v`` ``(..., 3)`` (``v`` crossed with its least-aligned
    coordinate axis); ``(1, 0, 0)`` for zero vectors."""
    v = np.asarray(v, dtype=np.float64)
    k = np.argmin(np.abs(v), axis=-1)
    e = np.zeros(v.shape)
    np.put_along_axis(e, k[..., None], 1.0, axis=-1)
    p, n = unit(np.cross(v, e))
    return np.where((n > EPS)[..., None], p, np.array([1.0, 0.0, 0.0]))


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of shape ``shape + (4,)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` for rotations by ``angle`` (radians, right-hand rule) about unit ``axis``
    ``(..., 3)``. A zero axis gives the identity."""
    axis = np.asarray(axis, dtype=np.float64)
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    return np.concatenate([axis * np.sin(half)[..., None], np.broadcast_to(np.cos(half), axis.shape[:-1])[..., None]], axis=-1)


def rotation_vector(q: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` (axis times angle in radians, angle in [0, pi]) of quaternions ``(..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    q = np.where(q[..., 3:4] < 0, -q, q)
    s = np.linalg.norm(q[..., :3], axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 3])
    scale = np.where(s > EPS, angle / np.where(s > EPS, s, 1.0), 2.0)  # small angles: 2*sin(a/2) ~ a
    return q[..., :3] * scale[..., None]


def angle_of(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians, in [0, pi], of quaternions ``(..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking the direction of ``a`` to the direction of ``b`` (both ``(..., 3)``,
    any length): axis ``a x b``, angle between them (seed 002, no reference point). Returns ``(..., 4)``.

    Anti-parallel vectors give a half turn about a vector perpendicular to ``a`` (:func:`perpendicular`);
    a zero-length ``a`` or ``b`` gives the identity.
    """
    ua, na = unit(a)
    ub, nb = unit(b)
    w = 1.0 + dot(ua, ub)
    xyz = np.cross(ua, ub)
    anti = w < _ANTI
    xyz = np.where(anti[..., None], perpendicular(ua), xyz)
    w = np.where(anti, 0.0, w)
    q = np.concatenate([xyz, w[..., None]], axis=-1)
    q /= np.sqrt(dot(q, q))[..., None]
    zero = (na <= EPS) | (nb <= EPS)
    return np.where(zero[..., None], identity(q.shape[:-1]), q)


def rotation_from_pairs(
    u1: np.ndarray, u2: np.ndarray, v1: np.ndarray, v2: np.ndarray, exact_first: bool = True
) -> np.ndarray:
    """The rotation taking rest vectors ``u1, u2`` to current vectors ``v1, v2`` (all ``(..., 3)``),
    seed 002 "with reference points". Returns quaternions ``(..., 4)``.

    The axis lies on the perpendicular-bisector plane of each pair (``axis . u_i = axis . v_i``), so it
    is ``(v1 - u1) x (v2 - u2)``; the angle is the one between the components of ``u_i`` and ``v_i``
    perpendicular to the axis (both pairs summed, so a pair lying on the axis does not matter).

    With ``exact_first`` (default) the second vector of each pair is first replaced by its component
    perpendicular to the first (Gram-Schmidt): the two pairs are then related by an exact rotation even
    when the measured angle between ``v1`` and ``v2`` differs from the rest one, ``v1`` is matched
    exactly and ``v2`` lies in the resulting plane. Without it, vectors are only normalised.

    Degenerate cases: a pair already aligned (``u_i == v_i``) puts the axis along ``u_i``; both aligned
    gives the identity; difference vectors parallel (axis, ``u1`` and ``u2`` coplanar, e.g. a half turn)
    takes the axis in the plane of ``u1, u2`` perpendicular to the differences; collinear reference
    vectors (``u1 || u2`` or ``v1 || v2``) carry no twist information, so the shortest arc ``u1 -> v1``
    is returned there.
    """
    u1, nu1 = unit(u1)
    v1, nv1 = unit(v1)
    u2 = np.asarray(u2, dtype=np.float64)
    v2 = np.asarray(v2, dtype=np.float64)
    if exact_first:
        u2 = u2 - dot(u2, u1)[..., None] * u1
        v2 = v2 - dot(v2, v1)[..., None] * v1
    u2, nu2 = unit(u2)
    v2, nv2 = unit(v2)
    # collinear reference points (or missing vectors): no full orientation available
    cu = np.linalg.norm(np.cross(u1, u2), axis=-1)
    cv = np.linalg.norm(np.cross(v1, v2), axis=-1)
    collinear = (cu < 1e-6) | (cv < 1e-6) | (nu1 <= EPS) | (nv1 <= EPS) | (nu2 <= EPS) | (nv2 <= EPS)

    d1 = v1 - u1
    d2 = v2 - u2
    d1u, n1 = unit(d1, 1e-9)
    d2u, n2 = unit(d2, 1e-9)
    z1, z2 = n1 <= 1e-9, n2 <= 1e-9
    axis = np.cross(d1u, d2u)
    an = np.linalg.norm(axis, axis=-1)
    # difference vectors parallel: the axis is in the plane of u1, u2 and perpendicular to d
    coplanar = (an < _PARALLEL) & ~z1 & ~z2
    axis = np.where(coplanar[..., None], np.cross(np.cross(u1, u2), d1u), axis)
    axis = np.where((z1 & ~z2)[..., None], u1, axis)
    axis = np.where((z2 & ~z1)[..., None], u2, axis)
    axis, axn = unit(axis)

    def perp(x: np.ndarray) -> np.ndarray:
        return x - dot(x, axis)[..., None] * axis

    pu1, pv1, pu2, pv2 = perp(u1), perp(v1), perp(u2), perp(v2)
    s = dot(axis, np.cross(pu1, pv1) + np.cross(pu2, pv2))
    c = dot(pu1, pv1) + dot(pu2, pv2)
    q = from_axis_angle(axis, np.arctan2(s, c))
    q = np.where(((z1 & z2) | (axn <= EPS))[..., None], identity(q.shape[:-1]), q)
    return np.where(collinear[..., None], shortest_arc(u1, v1), q)


def swing_twist(q: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split quaternions ``q`` ``(..., 4)`` into ``(swing, twist)`` with ``q = swing * twist``, where
    ``twist`` is a rotation about the unit ``axis`` ``(..., 3)`` (expressed in the frame ``q`` acts on)
    and ``swing`` a rotation about an axis perpendicular to it.

    When ``q`` is a half turn about an axis perpendicular to ``axis`` the twist is undefined: the
    identity is returned as twist.
    """
    q = np.asarray(q, dtype=np.float64)
    axis = np.asarray(axis, dtype=np.float64)
    proj = np.sum(q[..., :3] * axis, axis=-1, keepdims=True) * axis
    twist = np.concatenate([proj, q[..., 3:4]], axis=-1)
    n = np.linalg.norm(twist, axis=-1, keepdims=True)
    ok = n > 1e-9
    twist = np.where(ok, twist / np.where(ok, n, 1.0), identity(twist.shape[:-1]))
    swing = quat_mul(q, conj(twist))
    return swing, twist


def twist_angle(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Signed angle in radians, in (-pi, pi], of the twist part of ``q`` about unit ``axis`` (see :func:`swing_twist`)."""
    q = np.asarray(q, dtype=np.float64)
    s = np.sum(q[..., :3] * np.asarray(axis, dtype=np.float64), axis=-1)
    a = 2.0 * np.arctan2(s, q[..., 3])
    return np.where(a > np.pi, a - 2 * np.pi, np.where(a <= -np.pi, a + 2 * np.pi, a))


def continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs of quaternions ``(..., 4)`` along ``axis`` (frames) so consecutive ones are in the same
    hemisphere (``q`` and ``-q`` are the same rotation); the first frame is made ``w >= 0``."""
    q = np.asarray(q, dtype=np.float64)
    q = np.moveaxis(q, axis, 0)
    first = np.where(q[:1, ..., 3:4] < 0, -1.0, 1.0)
    d = np.sum(q[1:] * q[:-1], axis=-1, keepdims=True)
    flips = np.concatenate([first, np.where(d < 0, -1.0, 1.0)], axis=0)
    return np.moveaxis(q * np.cumprod(flips, axis=0), 0, axis)
