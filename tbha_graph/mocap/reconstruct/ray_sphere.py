"""``reconstruct.ray_sphere``: the seed's 3D skeleton from one camera (seed 000, sections 3.2-3.3).

All geometry is done in the camera frame (metres, x right, y down, z forward); a joint seen at pixel
``(u, v)`` lies on its ray ``P = Z·d`` with ``d = K⁻¹(u, v, 1)`` (undistorted first if the camera has
distortion) and ``Z`` its depth.

**First frame** (the take starts with a T-pose facing the camera): the triangle chest, left shoulder, right
shoulder is where the rays cross the actor's coronal plane, world z = ``plane_z``. ``plane_z = None`` fits the
plane's depth in closed form so the four torso bones around the chest (hips, neck, both shoulders) have
their lengths (distances on a plane at depth ``a`` from the camera scale with ``|a|``). With the camera of
``calibrate.tsai_coplanar`` the fit returns z = 0, the plane the calibration put the torso on, so this is
exactly the seed's first frame. The triangle's three side lengths measured here are kept for all frames.

**Later frames**: the triangle's three depths by damped Gauss-Newton on the three fixed side lengths,
started from the previous frame (seed: "gradient method from the previous frame").

**Expansion** (every frame, centre-out and top-down): each other joint is where its ray meets the sphere
around its already known neighbour (parent; the hips from the chest) with the bone length as radius:
``|Z·d − c|² = L²``, a quadratic ``A Z² − 2 B Z + C = 0`` with ``A = d·d``, ``B = d·c``, ``C = c·c − L²``.

* two roots: on the first frame take the one nearer the coronal plane (in a T-pose every limb lies in it);
  later, the one nearer the same joint in the previous frame (``continuity="previous"``, the seed), or nearer
  its constant-velocity prediction ``2·P[k−1] − P[k−2]`` (``continuity="velocity"``).
* one root: take it.
* no root (2D error, or a bone too short for what the image shows): lengthen the bone just enough, i.e. take
  the point of the ray closest to the sphere's centre, and count it per joint.

Joints not tracked in a frame are reconstructed from their predicted 2D (the tracker fills ``points``) and
marked ``tracked = False`` in the output. Frames are sequential only in the triangle's Gauss-Newton and in the
two-root choice (a two-state scan); everything else is vectorised over frames.

Measured limits (CMU 131_02, camera 4.5 m away, f = 800 px): exact on exact 2D with ``continuity="velocity"``;
the seed's rule picks the mirror root whenever a limb crosses the plane perpendicular to its ray (the two
roots meet there), tens of mm on exact 2D. The method has no redundancy: with 1 px of 2D noise, near-tangent
limbs (legs seen from the front) and the near-frontal triangle move by decimetres and branches flip; use
``reconstruct.sequence_lsq`` or smooth the 2D first.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..bundles.tracks import read_tracks
from ..camera import Camera
from ..ports import BODY, CAMERA, MOTION, TRACKS2D, report_port
from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, PARENTS, TRIANGLE_JOINTS
from ..body import body_lengths

_CHEST = JOINT_INDEX["chest"]
_TRI = np.array([JOINT_INDEX[j] for j in TRIANGLE_JOINTS])
_TORSO_BONES = tuple(JOINT_INDEX[j] for j in ("hips", "neck", "left_shoulder", "right_shoulder"))


def expansion_order() -> tuple[tuple[int, int], ...]:
    """``(joint, anchor)`` pairs, centre-out from the triangle, top-down: every anchor is known before its
    joint. Anchors are parents, except the hips (the root) whose anchor is the chest."""
    order: list[tuple[int, int]] = []
    known = set(int(j) for j in _TRI)
    frontier = [int(j) for j in _TRI]
    while frontier:
        nxt = []
        for a in frontier:
            neighbours = [int(c) for c in np.flatnonzero(PARENTS == a)]
            if PARENTS[a] >= 0:
                neighbours.append(int(PARENTS[a]))
            for j in sorted(neighbours):
                if j not in known:
                    known.add(j)
                    order.append((j, a))
                    nxt.append(j)
        frontier = nxt
    return tuple(order)


EXPANSION = expansion_order()


def bone_between(j: int, a: int, lengths: np.ndarray) -> float:
    """Length of the bone joining joints ``j`` and ``a`` (one is the other's parent), metres."""
    return float(lengths[j] if PARENTS[j] == a else lengths[a])


class RaySphereParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    plane_z: float | None = Field(None, description="world z of the actor's coronal plane on the first frame; None: fitted to the torso bone lengths", json_schema_extra={"unit": "m"})
    continuity: Literal["previous", "velocity"] = Field("previous", description="two-root choice after the first frame: nearer the previous position (seed) or the constant-velocity prediction")
    gn_iterations: int = Field(20, ge=1, le=200, description="Gauss-Newton iterations per frame for the triangle (at most)")


@dataclass
class RaySphereStats:
    """Counts for the report."""

    frames: int = 0
    plane_z: float = 0.0
    triangle_sides_m: list = field(default_factory=list)
    two_roots: dict = field(default_factory=dict)
    no_root: dict = field(default_factory=dict)
    max_lengthening_m: dict = field(default_factory=dict)
    triangle_residual_max_m: float = 0.0
    triangle_inexact: int = 0

    def as_report(self) -> dict:
        rep = {
            "frames": self.frames,
            "plane_z_m": self.plane_z,
            "triangle_sides_m": self.triangle_sides_m,
            "triangle_residual_max_m": self.triangle_residual_max_m,
            "triangle_inexact_frames": self.triangle_inexact,
            "two_root_total": int(sum(self.two_roots.values())),
            "no_root_total": int(sum(self.no_root.values())),
        }
        rep.update({f"two_roots_{k}": v for k, v in self.two_roots.items()})
        rep.update({f"no_root_{k}": v for k, v in self.no_root.items()})
        rep.update({f"max_lengthening_m_{k}": v for k, v in self.max_lengthening_m.items() if v > 0})
        return rep


def ray_directions(cam: Camera, pixels: np.ndarray) -> np.ndarray:
    """``(..., 3)`` camera-frame ray directions with z = 1 (so ``P = Z·d``) for pixels ``(..., 2)``."""
    px = np.asarray(pixels, dtype=np.float64)
    if np.any(cam.dist):
        import cv2

        flat = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.dist).reshape(px.shape)
    else:
        K = cam.K
        y = (px[..., 1] - K[1, 2]) / K[1, 1]
        x = (px[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        flat = np.stack([x, y], axis=-1)
    return np.concatenate([flat, np.ones(flat.shape[:-1] + (1,))], axis=-1)


def first_frame_torso(cam: Camera, d0: np.ndarray, lengths: np.ndarray, plane_z: float | None) -> tuple[np.ndarray, float]:
    """Camera-frame positions ``(N_JOINTS, 3)`` of all joints' rays crossing the coronal plane world z = plane_z
    on the first frame (only the torso entries are used), and the plane's z (fitted if ``None``, see module doc)."""
    w = d0 @ cam.R  # world directions of the rays (N_JOINTS, 3)
    cz = float(cam.center[2])
    wz = w[:, 2]
    used = np.concatenate([[_CHEST], _TRI, _TORSO_BONES])
    if np.any(np.abs(wz[used]) < 1e-12) or np.ptp(np.sign(wz[used])) > 0:
        raise NodeError("first frame: the torso rays do not all cross the actor's coronal plane",
                        hint="the take must start with a T-pose facing the camera (actor faces +z, camera in front)")
    q = w / wz[:, None]  # point on ray i at world z = cz + a  is  C + a q_i
    if plane_z is None:
        g = np.linalg.norm(q[list(_TORSO_BONES)] - q[_CHEST], axis=1)
        L = np.array([bone_between(j, _CHEST, lengths) for j in _TORSO_BONES])
        a = float(np.dot(g, L) / np.dot(g, g)) * float(np.sign(wz[_CHEST]))
        plane_z = cz + a
    a = plane_z - cz
    if np.any(a / wz[used] <= 0):
        raise NodeError(f"first frame: the coronal plane z = {plane_z:.3f} m is behind the camera",
                        hint="check the camera and plane_z")
    pts_world = cam.center + a * q
    return cam.to_camera(pts_world), float(plane_z)


def _sides(z1: float, z2: float, z3: float, d1, d2, d3):
    """Side vectors and lengths of the triangle P_i = Z_i d_i (plain floats, see track_triangle)."""
    e01 = (z1 * d1[0] - z2 * d2[0], z1 * d1[1] - z2 * d2[1], z1 * d1[2] - z2 * d2[2])
    e02 = (z1 * d1[0] - z3 * d3[0], z1 * d1[1] - z3 * d3[1], z1 * d1[2] - z3 * d3[2])
    e12 = (z2 * d2[0] - z3 * d3[0], z2 * d2[1] - z3 * d3[1], z2 * d2[2] - z3 * d3[2])
    n01 = (e01[0] * e01[0] + e01[1] * e01[1] + e01[2] * e01[2]) ** 0.5
    n02 = (e02[0] * e02[0] + e02[1] * e02[1] + e02[2] * e02[2]) ** 0.5
    n12 = (e12[0] * e12[0] + e12[1] * e12[1] + e12[2] * e12[2]) ** 0.5
    return e01, e02, e12, n01, n02, n12


def track_triangle(d: np.ndarray, z0: np.ndarray, sides: np.ndarray, iterations: int) -> tuple[np.ndarray, float, int]:
    """Depths ``(n, 3)`` of the triangle's joints on every frame, given rays ``d`` ``(n, 3, 3)`` (z = 1), the
    first frame's depths ``z0`` (3,) and the side lengths ``sides`` = (|P0 P1|, |P0 P2|, |P1 P2|).

    Frame k starts from frame k-1's depths and minimises ``sum (|Zi di − Zj dj| − D_ij)²`` by Gauss-Newton with
    Levenberg-Marquardt damping (a step is kept only if it lowers the cost), so where noise leaves no exact
    solution it settles at the nearest least-squares one instead of wandering. Plain Python floats: for a
    3x3 system per frame they are several times faster than numpy calls.
    Returns depths, the largest side-length residual (m) and the number of frames without an exact solution
    (a side off by more than 1 micrometre: noise made the three sides impossible for those rays).
    """
    n = d.shape[0]
    out = np.empty((n, 3))
    out[0] = z0
    D01, D02, D12 = (float(s) for s in sides)
    z1, z2, z3 = (float(v) for v in z0)
    dl = d.tolist()
    worst, inexact = 0.0, 0
    for k in range(1, n):
        d1, d2, d3 = dl[k]
        e01, e02, e12, n01, n02, n12 = _sides(z1, z2, z3, d1, d2, d3)
        r01, r02, r12 = n01 - D01, n02 - D02, n12 - D12
        cost = r01 * r01 + r02 * r02 + r12 * r12
        mu = 1e-6
        for _ in range(iterations):
            # Jacobian: d|ei-ej|/dZi = (ei-ej).di/|..|, d/dZj = -(ei-ej).dj/|..|
            j01a = (e01[0] * d1[0] + e01[1] * d1[1] + e01[2] * d1[2]) / n01
            j01b = -(e01[0] * d2[0] + e01[1] * d2[1] + e01[2] * d2[2]) / n01
            j02a = (e02[0] * d1[0] + e02[1] * d1[1] + e02[2] * d1[2]) / n02
            j02c = -(e02[0] * d3[0] + e02[1] * d3[1] + e02[2] * d3[2]) / n02
            j12b = (e12[0] * d2[0] + e12[1] * d2[1] + e12[2] * d2[2]) / n12
            j12c = -(e12[0] * d3[0] + e12[1] * d3[1] + e12[2] * d3[2]) / n12
            m11 = j01a * j01a + j02a * j02a
            m22 = j01b * j01b + j12b * j12b
            m33 = j02c * j02c + j12c * j12c
            m12, m13, m23 = j01a * j01b, j02a * j02c, j12b * j12c
            g1 = -(j01a * r01 + j02a * r02)
            g2 = -(j01b * r01 + j12b * r12)
            g3 = -(j02c * r02 + j12c * r12)
            improved = False
            while mu < 1e6:
                a11, a22, a33 = m11 * (1.0 + mu), m22 * (1.0 + mu), m33 * (1.0 + mu)
                c11 = a22 * a33 - m23 * m23
                c12 = m13 * m23 - m12 * a33
                c13 = m12 * m23 - m13 * a22
                det = a11 * c11 + m12 * c12 + m13 * c13
                if det <= 0.0:
                    mu *= 10.0
                    continue
                c22 = a11 * a33 - m13 * m13
                c23 = m12 * m13 - a11 * m23
                c33 = a11 * a22 - m12 * m12
                s1 = (c11 * g1 + c12 * g2 + c13 * g3) / det
                s2 = (c12 * g1 + c22 * g2 + c23 * g3) / det
                s3 = (c13 * g1 + c23 * g2 + c33 * g3) / det
                t = _sides(z1 + s1, z2 + s2, z3 + s3, d1, d2, d3)
                q01, q02, q12 = t[3] - D01, t[4] - D02, t[5] - D12
                new = q01 * q01 + q02 * q02 + q12 * q12
                if new <= cost:
                    z1, z2, z3 = z1 + s1, z2 + s2, z3 + s3
                    e01, e02, e12, n01, n02, n12 = t
                    r01, r02, r12, cost = q01, q02, q12, new
                    mu = max(mu * 0.3, 1e-9)
                    improved = True
                    break
                mu *= 10.0
            if not improved or abs(s1) + abs(s2) + abs(s3) < 1e-10 or cost < 1e-24:
                break
        if r01 * r01 + r02 * r02 + r12 * r12 > 1e-12:
            inexact += 1
        worst = max(worst, abs(r01), abs(r02), abs(r12))
        out[k, 0], out[k, 1], out[k, 2] = z1, z2, z3
    return out, worst, inexact


def _choose(cands: np.ndarray, first: int, continuity: str) -> np.ndarray:
    """Index ``(n,)`` of the chosen candidate per frame, ``cands`` ``(n, 2, 3)``; frame 0 takes ``first``.

    A scan over frames of a tiny automaton: the per-frame transition tables are computed vectorised."""
    n = cands.shape[0]
    choice = np.empty(n, dtype=np.int64)
    choice[0] = first
    if n == 1:
        return choice
    if continuity == "previous" or n == 2:
        # dist[k, a, b] = |cand_a[k] - cand_b[k-1]|: next[k][b] = argmin_a
        dist = np.linalg.norm(cands[1:, :, None, :] - cands[:-1, None, :, :], axis=-1)
        nxt = np.argmin(dist, axis=1).tolist()
        c = first
        for k in range(1, n):
            c = nxt[k - 1][c]
            choice[k] = c
        return choice
    # velocity: frame 1 by the previous-position rule, then prediction 2 P[k-1] - P[k-2]
    d1 = np.linalg.norm(cands[1] - cands[0, first], axis=-1)
    choice[1] = int(np.argmin(d1))
    pred = 2.0 * cands[1:-1, None, :, :] - cands[:-2, :, None, :]  # [k, b2 (k-2), b1 (k-1)]
    dist = np.linalg.norm(cands[2:, :, None, None, :] - pred[:, None], axis=-1)  # [k, a, b2, b1]
    nxt = np.argmin(dist, axis=1).tolist()  # [k][b2][b1]
    c2, c1 = int(choice[0]), int(choice[1])
    for k in range(2, n):
        c = nxt[k - 2][c2][c1]
        choice[k] = c
        c2, c1 = c1, c
    return choice


def solve_ray_sphere(
    pixels: np.ndarray,
    cam: Camera,
    lengths: np.ndarray,
    plane_z: float | None = None,
    continuity: str = "previous",
    gn_iterations: int = 20,
) -> tuple[np.ndarray, RaySphereStats]:
    """Joint positions ``(n, N_JOINTS, 3)`` metres **camera frame** from pixels ``(n, N_JOINTS, 2)``, a camera
    and bone lengths ``(N_JOINTS,)`` metres (see the module docstring). Also returns the counts."""
    pixels = np.asarray(pixels, dtype=np.float64)
    n = pixels.shape[0]
    d = ray_directions(cam, pixels)  # (n, 16, 3), z = 1
    P = np.zeros((n, N_JOINTS, 3))
    stats = RaySphereStats(frames=n)

    torso0, stats.plane_z = first_frame_torso(cam, d[0], lengths, plane_z)
    tri0 = torso0[_TRI]
    sides = np.array([np.linalg.norm(tri0[0] - tri0[1]), np.linalg.norm(tri0[0] - tri0[2]), np.linalg.norm(tri0[1] - tri0[2])])
    stats.triangle_sides_m = sides.tolist()
    depths, stats.triangle_residual_max_m, stats.triangle_inexact = track_triangle(d[:, _TRI], tri0[:, 2], sides, gn_iterations)
    P[:, _TRI] = depths[:, :, None] * d[:, _TRI]

    plane_normal = cam.R[:, 2]  # world +z in camera coordinates
    plane_offset = stats.plane_z + float(plane_normal @ cam.t)  # world z of Xc is n.Xc - n.t
    for j, a in EXPANSION:
        L = bone_between(j, a, lengths)
        c = P[:, a]
        dj = d[:, j]
        A = np.einsum("ij,ij->i", dj, dj)
        B = np.einsum("ij,ij->i", dj, c)
        C = np.einsum("ij,ij->i", c, c) - L * L
        disc = B * B - A * C
        none = disc < 0
        root = np.sqrt(np.where(none, 0.0, disc))
        z = np.stack([(B + root) / A, (B - root) / A], axis=1)  # (n, 2): far, near
        cands = z[:, :, None] * dj[:, None, :]
        # first frame: the root nearer the coronal plane (world z of Xc is n.(Xc - t))
        off = np.abs(cands[0] @ plane_normal - plane_offset)
        first = int(np.argmin(off))
        ch = _choose(cands, first, continuity)
        P[:, j] = cands[np.arange(n), ch]
        name = JOINT_NAMES[j]
        stats.two_roots[name] = int(np.count_nonzero(disc > 0))
        stats.no_root[name] = int(np.count_nonzero(none))
        if none.any():
            lengthened = np.linalg.norm(P[none, j] - c[none], axis=1) - L
            stats.max_lengthening_m[name] = float(lengthened.max())
        else:
            stats.max_lengthening_m[name] = 0.0
    return P, stats


@node(
    "reconstruct.ray_sphere",
    version=1,
    inputs={"tracks": TRACKS2D, "camera": CAMERA, "body": BODY},
    outputs={"motion": MOTION, "report": report_port("two-root choices, no-root lengthenings per joint, frames")},
    params=RaySphereParams,
)
def ray_sphere(ctx, tracks, camera, body):
    """3D joints by the seed's ray-sphere expansion from the shoulder triangle (one camera, known bones)."""
    p: RaySphereParams = ctx.params
    tr = read_tracks(tracks)
    cam = camera.camera()
    check_image_size(tr, cam)
    lengths = body_lengths(body)
    P, stats = solve_ray_sphere(tr.points, cam, lengths, p.plane_z, p.continuity, p.gn_iterations)
    return {"motion": motion_bundle(P, cam, tr), "report": stats.as_report()}


def motion_bundle(P: np.ndarray, cam: Camera, tr) -> dict:
    """The MOTION bundle of camera-frame joints ``P`` (n, 16, 3): world frame, the tracks' fps and flags."""
    return {"joints": cam.to_world(P), "fps": np.asarray(tr.fps, dtype=np.float64), "tracked": tr.tracked.copy(),
            "joint_names": np.array(JOINT_NAMES)}


def check_image_size(tr, cam: Camera) -> None:
    """The tracks and the camera must describe the same image size."""
    if (tr.width, tr.height) != (cam.width, cam.height):
        raise NodeError(
            f"the tracks are {tr.width}x{tr.height} px but the camera was calibrated for {cam.width}x{cam.height} px",
            hint="calibrate on the same (scaled) video the tracks come from",
        )
