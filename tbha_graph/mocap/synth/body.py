"""The renderer's body model: shaded volumes around the 16-joint skeleton, and the patch centres on it.

Every frame's body is a fixed list of primitives built from the joint positions (world frame, metres,
y up; see :mod:`tbha_graph.mocap.skeleton`). Each primitive is an **affine capsule**: the set of points
``p`` with ``dist(M (p - a), segment[0, M (b - a)]) <= 1`` for segment ends ``a``, ``b`` and a linear map
``M`` (3, 3). With ``M = I / r`` it is a round capsule of radius ``r`` (limbs, neck, girdles); with
``a = b`` it is an ellipsoid (pelvis, thorax, head); otherwise a capsule of elliptic cross-section
(the torso). ``M = diag(1 / radii) @ axes`` where the rows of ``axes`` are unit directions (width,
length, depth).

All functions are vectorised over leading frame axes: joints ``(n, 16, 3)`` give ends ``(n, P, 3)`` and
maps ``(n, P, 3, 3)``. The primitive order is fixed (:data:`PRIMITIVE_NAMES`), so a primitive id is
stable across frames.

Patches (seed 000: one coloured patch per joint but the head) lie on the surface: the patch centre is where
a ray from the joint along the joint's "front" direction leaves the outermost of the patch's allowed
primitives; the patch is the set of surface points of those primitives within ``patch_radius`` (3D) of
that centre, so it foreshortens as the surface turns and disappears when it faces away.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ..skeleton import JOINT_INDEX as J
from ..skeleton import PATCHED_JOINTS

PRIMITIVE_NAMES: tuple[str, ...] = (
    "neck",
    "shoulder_girdle",
    "hip_girdle",
    "left_upper_arm",
    "left_forearm",
    "left_hand",
    "right_upper_arm",
    "right_forearm",
    "right_hand",
    "left_thigh",
    "left_shin",
    "left_foot",
    "right_thigh",
    "right_shin",
    "right_foot",
    "pelvis",
    "torso",
    "thorax",
    "head",
)
N_PRIMITIVES = len(PRIMITIVE_NAMES)
PRIM: dict[str, int] = {n: i for i, n in enumerate(PRIMITIVE_NAMES)}

#: Material of each primitive: 0 suit, 1 hair (the dark head), 2 shoes.
MATERIAL_SUIT, MATERIAL_HAIR, MATERIAL_SHOE = 0, 1, 2
PRIMITIVE_MATERIAL: np.ndarray = np.array(
    [MATERIAL_HAIR if n == "head" else MATERIAL_SHOE if n.endswith("_foot") else MATERIAL_SUIT for n in PRIMITIVE_NAMES],
    dtype=np.int64,
)

#: Primitives each patch may lie on (order of PATCHED_JOINTS): the volumes meeting at that joint.
PATCH_PRIMITIVES: dict[str, tuple[str, ...]] = {
    "hips": ("pelvis", "torso", "hip_girdle"),
    "chest": ("torso", "thorax"),
    "neck": ("thorax", "torso", "neck", "shoulder_girdle"),
    "left_shoulder": ("thorax", "shoulder_girdle", "left_upper_arm"),
    "left_elbow": ("left_upper_arm", "left_forearm"),
    "left_wrist": ("left_forearm", "left_hand"),
    "right_shoulder": ("thorax", "shoulder_girdle", "right_upper_arm"),
    "right_elbow": ("right_upper_arm", "right_forearm"),
    "right_wrist": ("right_forearm", "right_hand"),
    "left_hip": ("pelvis", "hip_girdle", "left_thigh"),
    "left_knee": ("left_thigh", "left_shin"),
    "left_ankle": ("left_shin", "left_foot"),
    "right_hip": ("pelvis", "hip_girdle", "right_thigh"),
    "right_knee": ("right_thigh", "right_shin"),
    "right_ankle": ("right_shin", "right_foot"),
}
#: ``PATCH_ALLOWED[p, k]``: patch ``p`` (order of PATCHED_JOINTS) may colour primitive ``k``; shape (15, N_PRIMITIVES).
PATCH_ALLOWED: np.ndarray = np.zeros((len(PATCHED_JOINTS), N_PRIMITIVES), dtype=bool)
for _p, _j in enumerate(PATCHED_JOINTS):
    for _name in PATCH_PRIMITIVES[_j]:
        PATCH_ALLOWED[_p, PRIM[_name]] = True

_M = {"json_schema_extra": {"unit": "m"}}


class BodyShape(BaseModel):
    """Sizes of the body volumes, metres (a slim adult by default). Torso heights follow the skeleton's
    own trunk length (hips joint to the shoulder line); widths and depths are given here."""

    model_config = ConfigDict(extra="forbid")

    neck_radius: float = Field(0.05, gt=0, le=0.2, description="neck capsule radius", **_M)
    shoulder_girdle_radius: float = Field(0.055, gt=0, le=0.2, description="radius of the capsule joining the shoulders", **_M)
    hip_girdle_radius: float = Field(0.075, gt=0, le=0.3, description="radius of the capsule joining the hip joints", **_M)
    upper_arm_radius: float = Field(0.048, gt=0, le=0.2, description="upper arm capsule radius", **_M)
    forearm_radius: float = Field(0.038, gt=0, le=0.2, description="forearm capsule radius", **_M)
    hand_radius: float = Field(0.035, gt=0, le=0.2, description="hand (mitten) capsule radius", **_M)
    hand_length: float = Field(0.09, ge=0, le=0.3, description="hand capsule length beyond the wrist", **_M)
    thigh_radius: float = Field(0.068, gt=0, le=0.3, description="thigh capsule radius", **_M)
    shin_radius: float = Field(0.048, gt=0, le=0.2, description="shin capsule radius", **_M)
    foot_radius: float = Field(0.035, gt=0, le=0.1, description="foot capsule radius", **_M)
    foot_length: float = Field(0.16, gt=0, le=0.4, description="heel-to-toe length of the foot capsule", **_M)
    ankle_height: float = Field(0.08, gt=0, le=0.2, description="ankle joint centre above the sole", **_M)
    pelvis_half_width: float = Field(0.15, gt=0, le=0.4, description="pelvis ellipsoid half width", **_M)
    pelvis_half_depth: float = Field(0.105, gt=0, le=0.3, description="pelvis ellipsoid half depth", **_M)
    torso_half_width: float = Field(0.145, gt=0, le=0.4, description="torso (waist to chest) half width", **_M)
    torso_half_depth: float = Field(0.095, gt=0, le=0.3, description="torso half depth", **_M)
    thorax_half_width: float = Field(0.165, gt=0, le=0.4, description="thorax ellipsoid half width", **_M)
    thorax_half_depth: float = Field(0.105, gt=0, le=0.3, description="thorax ellipsoid half depth", **_M)
    head_radii: tuple[float, float, float] = Field(
        (0.08, 0.11, 0.097), description="head ellipsoid half width, half height, half depth", **_M
    )


@dataclass
class BodyGeometry:
    """Primitives of a batch of frames (world or camera frame, metres): segment ends ``a``, ``b``
    (n, P, 3), linear maps ``M`` (n, P, 3, 3) to the unit-radius capsule's space, and ``round_r`` (P,)
    the radius of round capsules (0 for the others), which the rasteriser draws on a faster path."""

    a: np.ndarray
    b: np.ndarray
    M: np.ndarray
    round_r: np.ndarray

    def transformed(self, R: np.ndarray, t: np.ndarray) -> "BodyGeometry":
        """The same primitives after the rigid motion ``x -> R x + t`` (e.g. world -> camera)."""
        return BodyGeometry(a=self.a @ R.T + t, b=self.b @ R.T + t, M=self.M @ R.T, round_r=self.round_r)


def _unit(v: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps)


def _perp(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Component of ``v`` perpendicular to unit ``axis`` (both (..., 3))."""
    return v - np.sum(v * axis, axis=-1, keepdims=True) * axis


def _frame_from(up: np.ndarray, left: np.ndarray) -> np.ndarray:
    """Orthonormal axes (..., 3, 3), rows (left/width, up/height, front/depth), front = left x up."""
    y = _unit(up)
    x = _unit(_perp(left, y))
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-2)


def body_frames(joints: np.ndarray) -> dict[str, np.ndarray]:
    """Orientation frames (..., 3, 3) (rows: left, up, front) of the pelvis and the thorax, and the
    body's ``front`` direction (..., 3), from joints (..., 16, 3) world metres."""
    j = np.asarray(joints, dtype=np.float64)
    hip_left = j[..., J["left_hip"], :] - j[..., J["right_hip"], :]
    sh_left = j[..., J["left_shoulder"], :] - j[..., J["right_shoulder"], :]
    pelvis = _frame_from(j[..., J["chest"], :] - j[..., J["hips"], :], hip_left)
    thorax = _frame_from(j[..., J["neck"], :] - j[..., J["chest"], :], sh_left)
    return {"pelvis": pelvis, "thorax": thorax, "front": _unit(pelvis[..., 2, :] + thorax[..., 2, :])}


def _affine(axes: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``diag(1 / radii) @ axes`` for axes (..., 3, 3) rows and radii (..., 3)."""
    return axes / np.asarray(radii)[..., :, None]


def build_body(joints: np.ndarray, shape: BodyShape | None = None) -> BodyGeometry:
    """Primitives of the body for joints ``(n, 16, 3)`` world metres, order of :data:`PRIMITIVE_NAMES`."""
    s = shape or BodyShape()
    j = np.asarray(joints, dtype=np.float64)
    P = {name: j[..., i, :] for name, i in J.items()}
    fr = body_frames(j)
    pelvis_f, thorax_f = fr["pelvis"], fr["thorax"]
    lead = j.shape[:-2]
    eye = np.broadcast_to(np.eye(3), lead + (3, 3))
    world_up = np.array([0.0, 1.0, 0.0])
    # the foot points forward (pelvis front, flattened on the floor) and its sole is ankle_height down
    fwd = _unit(_perp(pelvis_f[..., 2, :], world_up) + 1e-6 * pelvis_f[..., 2, :])
    drop = (s.ankle_height - s.foot_radius) * world_up

    prims: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}

    def round_capsule(name: str, a: np.ndarray, b: np.ndarray, r: float) -> None:
        prims[name] = (a, b, eye / r, r)

    def ellipsoid(name: str, c: np.ndarray, axes: np.ndarray, radii) -> None:
        prims[name] = (c, c, _affine(axes, np.broadcast_to(radii, lead + (3,))), 0.0)

    round_capsule("neck", P["neck"], P["head"], s.neck_radius)
    round_capsule("shoulder_girdle", P["left_shoulder"], P["right_shoulder"], s.shoulder_girdle_radius)
    round_capsule("hip_girdle", P["left_hip"], P["right_hip"], s.hip_girdle_radius)
    for side in ("left", "right"):
        sh, el, wr = P[f"{side}_shoulder"], P[f"{side}_elbow"], P[f"{side}_wrist"]
        round_capsule(f"{side}_upper_arm", sh, el, s.upper_arm_radius)
        round_capsule(f"{side}_forearm", el, wr, s.forearm_radius)
        round_capsule(f"{side}_hand", wr, wr + s.hand_length * _unit(wr - el), s.hand_radius)
    for side in ("left", "right"):
        hp, kn, an = P[f"{side}_hip"], P[f"{side}_knee"], P[f"{side}_ankle"]
        round_capsule(f"{side}_thigh", hp, kn, s.thigh_radius)
        round_capsule(f"{side}_shin", kn, an, s.shin_radius)
        heel = an - 0.25 * s.foot_length * fwd - drop
        round_capsule(f"{side}_foot", heel, heel + s.foot_length * fwd, s.foot_radius)

    hips, neck = P["hips"], P["neck"]
    shoulders = 0.5 * (P["left_shoulder"] + P["right_shoulder"])
    trunk = np.linalg.norm(shoulders - hips, axis=-1)  # hips joint to the shoulder line
    ones = np.ones_like(trunk)
    ellipsoid("pelvis", hips, pelvis_f, np.stack([s.pelvis_half_width * ones, 0.36 * trunk, s.pelvis_half_depth * ones], -1))
    # torso: capsule of elliptic cross-section from above the pelvis to the chest
    ta = hips + 0.15 * (shoulders - hips)
    tb = hips + 0.75 * (shoulders - hips)
    torso_axes = _frame_from(tb - ta, thorax_f[..., 0, :] + pelvis_f[..., 0, :])
    cap = np.minimum(s.torso_half_width, s.torso_half_depth)
    prims["torso"] = (ta, tb, _affine(torso_axes, np.array([s.torso_half_width, cap, s.torso_half_depth])), 0.0)
    ellipsoid("thorax", hips + 0.8 * (shoulders - hips), thorax_f,
              np.stack([s.thorax_half_width * ones, 0.42 * trunk, s.thorax_half_depth * ones], -1))
    head_dir = _unit(P["head"] - neck)
    ellipsoid("head", P["head"] + 0.6 * s.head_radii[1] * head_dir, _frame_from(head_dir, thorax_f[..., 0, :]), np.array(s.head_radii))

    order = [prims[name] for name in PRIMITIVE_NAMES]
    return BodyGeometry(
        a=np.stack([np.broadcast_to(p[0], lead + (3,)) for p in order], axis=-2),
        b=np.stack([np.broadcast_to(p[1], lead + (3,)) for p in order], axis=-2),
        M=np.stack([np.broadcast_to(p[2], lead + (3, 3)) for p in order], axis=-3),
        round_r=np.array([p[3] for p in order]),
    )


# --------------------------------------------------------------------------------------------
# rays leaving the body from inside (patch placement)
# --------------------------------------------------------------------------------------------
def _sphere_roots(o: np.ndarray, d: np.ndarray, c: np.ndarray, r) -> tuple[np.ndarray, np.ndarray]:
    """Near and far roots of |o + t d - c| = r for unit d; (+inf, -inf) where the ray misses."""
    oc = o - c
    b = np.sum(oc * d, axis=-1)
    disc = b * b - (np.sum(oc * oc, axis=-1) - np.asarray(r) ** 2)
    s = np.sqrt(np.maximum(disc, 0.0))
    hit = disc >= 0
    return np.where(hit, -b - s, np.inf), np.where(hit, -b + s, -np.inf)


def _capsule_roots(o: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray, r) -> tuple[np.ndarray, np.ndarray]:
    """Where the ray ``o + t d`` (unit d) enters and leaves the round capsule (a, b, r): (t_in, t_out),
    (+inf, -inf) if it misses. A capsule is convex, the union of a finite cylinder and two balls: it is
    entered at the smallest entry of its parts and left at the largest exit."""
    axis = b - a
    length = np.linalg.norm(axis, axis=-1)
    u = axis / np.maximum(length, 1e-12)[..., None]
    oa = o - a
    dp = _perp(d, u)
    op = _perp(oa, u)
    A = np.sum(dp * dp, axis=-1)
    B = np.sum(dp * op, axis=-1)
    C = np.sum(op * op, axis=-1) - np.asarray(r) ** 2
    disc = B * B - A * C
    ok = (disc >= 0) & (A > 1e-12)
    s = np.sqrt(np.maximum(disc, 0.0))
    A1 = np.where(A > 1e-12, A, 1.0)
    t_cyl = []
    for t in ((-B - s) / A1, (-B + s) / A1):
        along = np.sum((oa + np.where(ok, t, 0.0)[..., None] * d) * u, axis=-1)
        t_cyl.append(ok & (along >= 0) & (along <= length))
        t_cyl.append(t)
    in_a, out_a = _sphere_roots(o, d, a, r)
    in_b, out_b = _sphere_roots(o, d, b, r)
    t_in = np.minimum(np.where(t_cyl[0], t_cyl[1], np.inf), np.minimum(in_a, in_b))
    t_out = np.maximum(np.where(t_cyl[2], t_cyl[3], -np.inf), np.maximum(out_a, out_b))
    return t_in, t_out


def primitive_roots(o: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances (...,) along unit ``d`` from ``o`` to where the ray enters and leaves the affine capsule
    (a, b, M) (world units: the map is linear, so only the direction's length changes, which is divided
    out); (+inf, -inf) where it misses. Broadcasts over leading axes."""
    ol = np.einsum("...ij,...j->...i", M, o - a)
    dl = np.einsum("...ij,...j->...i", M, d)
    bl = np.einsum("...ij,...j->...i", M, b - a)
    scale = np.linalg.norm(dl, axis=-1)
    t_in, t_out = _capsule_roots(ol, dl / scale[..., None], np.zeros_like(bl), bl, 1.0)
    return t_in / scale, t_out / scale


def patch_directions(joints: np.ndarray) -> np.ndarray:
    """Unit outward direction (n, 15, 3) of each patch (order of PATCHED_JOINTS): the body's front,
    made perpendicular to the limb at limb joints (falling back towards the torso's up direction when
    the limb points straight forward); at the ankles it is kept from pointing downwards, so the patch
    stays on the lower shin when the shin tilts (the model's foot stays level)."""
    j = np.asarray(joints, dtype=np.float64)
    fr = body_frames(j)
    front_p, front_t = fr["pelvis"][..., 2, :], fr["thorax"][..., 2, :]
    up_t = fr["thorax"][..., 1, :]
    limb = {  # joint -> (bone ends whose directions are averaged)
        "left_elbow": ("left_shoulder", "left_elbow", "left_wrist"),
        "left_wrist": ("left_elbow", "left_wrist", "left_wrist"),
        "right_elbow": ("right_shoulder", "right_elbow", "right_wrist"),
        "right_wrist": ("right_elbow", "right_wrist", "right_wrist"),
        "left_knee": ("left_hip", "left_knee", "left_ankle"),
        "left_ankle": ("left_knee", "left_ankle", "left_ankle"),
        "right_knee": ("right_hip", "right_knee", "right_ankle"),
        "right_ankle": ("right_knee", "right_ankle", "right_ankle"),
        "left_shoulder": ("left_shoulder", "left_shoulder", "left_elbow"),
        "right_shoulder": ("right_shoulder", "right_shoulder", "right_elbow"),
        "left_hip": ("left_hip", "left_hip", "left_knee"),
        "right_hip": ("right_hip", "right_hip", "right_knee"),
    }
    out = []
    for name in PATCHED_JOINTS:
        front = front_p if name in ("hips", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle") else front_t
        if name not in limb:
            out.append(front)
            continue
        a, m, b = (j[..., J[k], :] for k in limb[name])
        axis = _unit(_unit(m - a) + _unit(b - m))
        f = _perp(front, axis)
        fn = np.linalg.norm(f, axis=-1, keepdims=True)
        g = _perp(up_t if "wrist" in name or "elbow" in name or "shoulder" in name else -up_t, axis)
        w = np.clip(0.3 - fn, 0.0, 0.3) / 0.3
        n = _unit(f + w * _unit(g))
        if "ankle" in name:  # keep the ankle patch on the lower shin, above the (always level) foot
            n = _unit(n - np.minimum(n[..., 1:2], 0.0) * np.array([0.0, 1.0, 0.0]))
        out.append(n)
    return np.stack(out, axis=-2)


def patch_centres(joints: np.ndarray, body: BodyGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Patch centres on the surface (n, 15, 3) and their outward directions (n, 15, 3), world metres."""
    j = np.asarray(joints, dtype=np.float64)
    dirs = patch_directions(j)
    centres = np.empty_like(dirs)
    for p, name in enumerate(PATCHED_JOINTS):
        o, d = j[..., J[name], :], dirs[..., p, :]
        t = np.full(o.shape[:-1], -np.inf)
        for prim in PATCH_PRIMITIVES[name]:
            k = PRIM[prim]
            t = np.maximum(t, primitive_roots(o, d, body.a[..., k, :], body.b[..., k, :], body.M[..., k, :, :])[1])
        t = np.where(np.isfinite(t), t, 0.0)
        centres[..., p, :] = o + t[..., None] * d
    return centres, dirs
