"""``reconstruct.temporal_ray_sphere``: the seed's ray-sphere skeleton, made robust to 2D noise over time.

Same geometry as :mod:`.ray_sphere` (camera frame, rays ``d``, spheres of bone length around the known
neighbour), but the two quantities the seed solves frame by frame are estimated over the whole take:

1. **Torso pose.** The torso (hips, chest, neck, shoulders, hip joints) is a nearly rigid body whose
   shape is the T-pose built from the bone lengths (:func:`.body.tpose_on_floor`, the shape the
   calibration assumes too). Its pose on every frame is a perspective-n-point fit of that shape to the
   tracked torso joints (``cv2.solvePnP``, iterative, the first frame from the camera's extrinsics, each
   next from the previous pose), and the pose's translation and rotation are then low-pass filtered
   (``torso_cutoff`` Hz, zero phase).
2. **Limb depths.** For a joint on the ray with unit direction ``u`` around a known neighbour ``c``, the
   ray-sphere roots are ``t = u·c ± √D`` with ``D = L² − |c − (u·c) u|²``. Frame by frame, the square
   root turns pixel noise into decimetres near tangency (``D ≈ 0``: a limb seen side-on, e.g. the legs
   from the front). Here ``D`` — linear in the noise — is low-pass filtered over time (``limb_cutoff``)
   before the root is taken, and the sign of ``±√D`` (in front of / behind the neighbour) is chosen for
   the whole take at once by dynamic programming (Viterbi over frames): a sign path whose signed offset
   ``s = ±√D`` has the smallest second differences (smooth velocity), plus an anatomical cost at the
   knees and elbows (a knee does not bend forward, an elbow not backward), instead of the seed's
   frame-to-frame nearest-root rule.

**Depth-flip timeline.** Output ``sides`` holds the side chosen per (frame, joint) (``viz.depth_sides`` draws
it as a PNG strip); param ``overrides`` pins a joint's side over a frame range where the solver chose
wrong (``[{joint: left_elbow, frames: [120, 180], side: front}]``): only those frames of that joint (and
the joints hanging from it) change, and only this node and those downstream run again.

Output: joints in the world frame (metres) with ``tracked`` from the tracks; ``report`` counts the frames
where ``D < 0`` (bone too short for what the image shows: the point of the ray nearest the sphere is
taken) and the sign flips per joint. Vectorised over frames except the Viterbi scan (4 states per frame)
and the per-frame PnP.
"""
from __future__ import annotations

import numpy as np
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ...core.errors import NodeError
from ...core.node import node
from ..bundles.tracks import read_tracks
from ..camera import Camera
from ..lowpass import butterworth_lowpass
from ..ports import BODY, CAMERA, MOTION, SIDES, TRACKS2D, report_port
from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, PARENTS
from ..body import body_lengths, tpose_on_floor
from .ray_sphere import bone_between, check_image_size, motion_bundle, ray_directions

TORSO = tuple(JOINT_INDEX[n] for n in ("hips", "chest", "neck", "left_shoulder", "right_shoulder", "left_hip", "right_hip"))
#: hinge joints: (joint, sign of (inside-of-bend · body forward) that is anatomically natural)
HINGES = {JOINT_INDEX["left_knee"]: -1.0, JOINT_INDEX["right_knee"]: -1.0,
          JOINT_INDEX["left_elbow"]: 1.0, JOINT_INDEX["right_elbow"]: 1.0}


class SidePin(BaseModel):
    """Pin the depth side of one joint over a frame range (both ends included)."""

    model_config = ConfigDict(extra="forbid")
    joint: str = Field(description="joint whose side is pinned (a limb or head joint)")
    frames: tuple[int, int] = Field(description="first and last frame, inclusive")
    side: Literal["front", "back"] = Field(description="front: nearer the camera than its parent joint; back: farther")

    @field_validator("joint")
    @classmethod
    def _known(cls, v: str) -> str:
        if v not in JOINT_INDEX or JOINT_INDEX[v] in TORSO:
            from ...core.errors import did_you_mean

            limbs = [n for n in JOINT_NAMES if JOINT_INDEX[n] not in TORSO]
            raise ValueError(f"{v!r} is not a limb or head joint{did_you_mean(v, limbs)}; pinnable: {', '.join(limbs)}")
        return v

    @model_validator(mode="after")
    def _range(self) -> "SidePin":
        if not 0 <= self.frames[0] <= self.frames[1]:
            raise ValueError(f"frames {list(self.frames)} must be [first, last] with 0 <= first <= last")
        return self


class TemporalRaySphereParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    torso_cutoff: float = Field(3.0, gt=0, description="low-pass cutoff of the torso pose over time", json_schema_extra={"unit": "Hz"})
    limb_cutoff: float = Field(4.0, gt=0, description="low-pass cutoff of each limb's squared depth offset D", json_schema_extra={"unit": "Hz"})
    hinge_weight: float = Field(1.0, ge=0, description="weight of the knee/elbow bending-direction cost against smoothness")
    overrides: list[SidePin] = Field(
        default_factory=list,
        description="pin a joint's depth side over frames, e.g. [{joint: left_elbow, frames: [120, 180], side: front}]; "
        "the solver's own choice is kept everywhere else",
    )


def lowpass(x: np.ndarray, fps: float, cutoff: float) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (returned unchanged if the cutoff is at Nyquist or above)."""
    if cutoff >= fps / 2 or x.shape[0] < 16:
        return x.copy()
    return butterworth_lowpass(x, fps, cutoff, order=2, padlen=15)


def torso_poses(cam: Camera, pixels: np.ndarray, shape: np.ndarray, fps: float, cutoff: float) -> np.ndarray:
    """Camera-frame torso joints ``(n, 7, 3)``: the rigid ``shape`` (7, 3) (world frame, T-pose at the start
    position) fitted to ``pixels`` (n, 7, 2) by PnP on each frame (from the previous pose; the first from the
    camera's own extrinsics), the pose low-pass filtered over time."""
    import cv2
    from scipy.spatial.transform import Rotation

    centre = shape.mean(axis=0)
    obj = np.ascontiguousarray(shape - centre, dtype=np.float64)
    n = pixels.shape[0]
    K = np.ascontiguousarray(cam.K, dtype=np.float64)
    dist = np.ascontiguousarray(cam.dist, dtype=np.float64) if np.any(cam.dist) else None
    rvec = cv2.Rodrigues(np.ascontiguousarray(cam.R))[0]
    tvec = np.ascontiguousarray((cam.R @ centre + cam.t).reshape(3, 1), dtype=np.float64)
    rvecs, tvecs = np.empty((n, 3)), np.empty((n, 3))
    for k in range(n):
        img = np.ascontiguousarray(pixels[k], dtype=np.float64)
        ok, r, t = cv2.solvePnP(obj, img, K, dist, rvec.copy(), tvec.copy(), useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        if ok and np.isfinite(r).all() and np.isfinite(t).all() and t[2, 0] > 0:
            rvec, tvec = r, t
        rvecs[k], tvecs[k] = rvec[:, 0], tvec[:, 0]
    quats = Rotation.from_rotvec(rvecs).as_quat()
    flip = np.cumprod(np.where(np.einsum("ij,ij->i", quats[1:], quats[:-1]) < 0, -1.0, 1.0))
    quats[1:] *= flip[:, None]  # a continuous quaternion path, so it can be filtered
    quats = lowpass(quats, fps, cutoff)
    R = Rotation.from_quat(quats / np.linalg.norm(quats, axis=1, keepdims=True)).as_matrix()
    t = lowpass(tvecs, fps, cutoff)
    return np.einsum("nij,kj->nki", R, obj) + t[:, None, :]


def choose_signs(s_abs: np.ndarray, hinge_cost: np.ndarray | None, weight: float) -> np.ndarray:
    """Signs ``(n,)`` in {+1, -1} minimising ``sum (s_k - 2 s_(k-1) + s_(k-2))² + weight · hinge_cost``, with
    ``s = sign · s_abs`` (Viterbi over pairs of consecutive signs). ``hinge_cost`` ``(n, 2)``: per-frame cost
    of sign +1 / -1 (anatomy), or None."""
    n = s_abs.shape[0]
    signs = np.array([1.0, -1.0])
    node_cost = np.zeros((n, 2)) if hinge_cost is None else weight * hinge_cost
    if n == 1:
        return signs[[int(np.argmin(node_cost[0]))]]
    # state at frame k: (sign index at k-1, sign index at k); cost[a, b]
    cost = node_cost[0][:, None] + node_cost[1][None, :]
    back = np.zeros((n, 2, 2), dtype=np.int64)
    sv = s_abs[:, None] * signs[None, :]  # (n, 2) signed values
    for k in range(2, n):
        # transition (a, b) -> (b, c): second difference of sv[k-2][a], sv[k-1][b], sv[k][c]
        dd = sv[k][None, None, :] - 2.0 * sv[k - 1][None, :, None] + sv[k - 2][:, None, None]  # [a, b, c]
        total = cost[:, :, None] + dd * dd + node_cost[k][None, None, :]
        back[k] = np.argmin(total, axis=0)  # best a for (b, c)
        cost = np.min(total, axis=0)
    b, c = np.unravel_index(int(np.argmin(cost)), cost.shape)
    idx = np.empty(n, dtype=np.int64)
    idx[n - 1], idx[n - 2] = c, b
    for k in range(n - 1, 1, -1):
        idx[k - 2] = back[k][idx[k - 1], idx[k]]
    return signs[idx]


def solve_temporal(pixels: np.ndarray, cam: Camera, lengths: np.ndarray, fps: float, p: TemporalRaySphereParams,
                   torso: np.ndarray | None = None) -> tuple[np.ndarray, dict, np.ndarray]:
    """Joints ``(n, 16, 3)`` camera frame (metres), a report, and the depth side chosen per (frame, joint)
    ``(n, 16)`` int8 (-1 nearer the camera than the parent, +1 farther, 0 torso); see the module docstring.
    ``torso`` ``(n, 7, 3)`` camera frame (joints :data:`TORSO`) replaces step 1 when given."""
    d = ray_directions(cam, pixels)  # z = 1
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    n = pixels.shape[0]
    idx = np.array(TORSO)
    P = np.zeros((n, N_JOINTS, 3))
    P[:, idx] = torso_poses(cam, pixels[:, idx], tpose_on_floor(lengths)[idx], fps, p.torso_cutoff) if torso is None else torso
    forward = np.cross(P[:, JOINT_INDEX["left_shoulder"]] - P[:, JOINT_INDEX["right_shoulder"]],
                       P[:, JOINT_INDEX["neck"]] - P[:, JOINT_INDEX["chest"]])
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)  # actor's forward, camera frame (left x up)
    known = set(TORSO)
    report: dict = {"frames": n}
    sides = np.zeros((n, N_JOINTS), dtype=np.int8)
    order = [j for j in range(N_JOINTS) if j not in known]
    while order:
        for j in list(order):
            a = int(PARENTS[j]) if PARENTS[j] >= 0 else JOINT_INDEX["chest"]  # the root hangs from the chest
            if a not in known:
                continue
            L = bone_between(j, a, lengths)
            c = P[:, a]
            uc = np.einsum("ij,ij->i", u[:, j], c)
            D = L * L - (np.einsum("ij,ij->i", c, c) - uc * uc)
            Ds = lowpass(D, fps, p.limb_cutoff)
            s_abs = np.sqrt(np.clip(Ds, 0.0, None))
            hinge = None
            if a in HINGES and PARENTS[a] >= 0:
                g = P[:, int(PARENTS[a])]  # grandparent (hip / shoulder)
                cost = np.zeros((n, 2))
                for col, sg in enumerate((1.0, -1.0)):
                    X = (uc + sg * s_abs)[:, None] * u[:, j]
                    inside = (g - c) / np.linalg.norm(g - c, axis=1, keepdims=True) + (X - c) / max(L, 1e-9)
                    cost[:, col] = np.clip(-HINGES[a] * np.einsum("ij,ij->i", inside, forward), 0.0, None) ** 2
                hinge = cost * (L * L)
            sign = choose_signs(s_abs, hinge, p.hinge_weight)
            for pin in p.overrides:
                if JOINT_INDEX[pin.joint] == j:  # the user's word wins on the pinned frames only
                    sign[pin.frames[0] : pin.frames[1] + 1] = -1.0 if pin.side == "front" else 1.0
            sides[:, j] = sign.astype(np.int8)
            P[:, j] = (uc + sign * s_abs)[:, None] * u[:, j]
            report[f"no_root_{JOINT_NAMES[j]}"] = int(np.count_nonzero(Ds < 0))
            report[f"flips_{JOINT_NAMES[j]}"] = int(np.count_nonzero(np.diff(sign) != 0))
            known.add(j)
            order.remove(j)
    return P, report, sides


@node(
    "reconstruct.temporal_ray_sphere",
    version=1,
    inputs={"tracks": TRACKS2D, "camera": CAMERA, "body": BODY},
    outputs={
        "motion": MOTION,
        "report": report_port("no-root frames and depth-sign flips per joint"),
        "sides": SIDES,
    },
    params=TemporalRaySphereParams,
)
def temporal_ray_sphere(ctx, tracks, camera, body):
    """3D joints by ray-sphere expansion with the torso pose and limb depths estimated over time (robust to 2D noise)."""
    p: TemporalRaySphereParams = ctx.params
    tr = read_tracks(tracks)
    cam = camera.camera()
    check_image_size(tr, cam)
    if tr.fps is None or not np.isfinite(tr.fps) or tr.fps <= 0:
        raise NodeError("the tracks have no frame rate", hint="the tracking node must give 'fps'")
    n = tr.points.shape[0]
    late = [pin for pin in p.overrides if pin.frames[1] >= n]
    if late:
        raise NodeError(f"override {late[0].model_dump()} reaches frame {late[0].frames[1]} but the take has {n} frames (0-{n - 1})")
    P, report, sides = solve_temporal(tr.points, cam, body_lengths(body), float(tr.fps), p)
    return {"motion": motion_bundle(P, cam, tr), "report": report,
            "sides": {"sides": sides, "joint_names": np.array(JOINT_NAMES), "fps": np.asarray(tr.fps, dtype=np.float64)}}
