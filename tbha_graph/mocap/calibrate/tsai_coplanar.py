"""``calibrate.tsai_coplanar``: the seed's coplanar 5-point Tsai calibration on the T-pose torso.

Method (seed 000, section 3.1; Tsai 1987, coplanar case, no lens distortion, square pixels):

1. Image points ``(Xd, Yd)`` in pixels relative to the image centre ``((w-1)/2, (h-1)/2)``, x right,
   y down, averaged over the first T-pose frames, of neck, chest, hips, left and right shoulder.
2. World points ``(Xw, Yw, 0)`` of the same joints from the bone lengths: the rest T-pose of
   :func:`tbha_graph.mocap.body.tpose_on_floor`. **World frame of the output camera**:
   metres, y up, x = actor's left, the actor faces +z, the torso (coronal) plane is z = 0 and the origin
   is on the floor (y = 0) straight below the hips joint, whose height is the leg length plus
   ``ankle_height``. Putting the origin on the floor rather than at the torso keeps ``Ty`` (the height of the
   origin below the optical axis) well away from 0, which the method divides by.
3. Radial alignment: per point ``Yd·Xw·a1 + Yd·Yw·a2 + Yd·a3 − Xd·Xw·a4 − Xd·Yw·a5 = Xd`` with
   ``a = (r1, r2, Tx, r4, r5) / Ty`` (least squares; exactly determined by 5 points).
4. ``|Ty|`` from the orthonormality of R's upper-left 2×2 block (Tsai's coplanar formula); the sign of
   ``Ty`` from the point farthest from the image centre: with ``Ty > 0`` its ``(x, y) = (r1 Xw + r2 Yw + Tx,
   r4 Xw + r5 Yw + Ty)`` must point the same way as ``(Xd, Yd)`` (tested as a positive dot product, which
   equals the seed's sign test on exact data and does not break when one coordinate is near 0).
5. ``r3 = +sqrt(1 − r1² − r2²)``, ``r6 = −sgn(r1 r4 + r2 r5)·sqrt(1 − r4² − r5²)``; third row = row1 × row2;
   R is then projected onto the nearest rotation (SVD) so noise cannot make it non-orthonormal.
6. ``f`` and ``Tz`` from ``(y_i, −Yd_i)·(f, Tz)ᵀ = w_i·Yd_i`` (least squares). If ``f < 0`` the coplanar sign
   ambiguity picked the wrong ``r3, r6``: flip them (and ``r7, r8``) and solve again.

Known limit (reported, not hidden): ``f`` and ``Tz`` are separable only through perspective foreshortening
of the torso plane (the ``w_i`` terms). A torso exactly parallel to the image plane (camera at chest height
looking at the chest) makes them inseparable, and the three collinear spine points projecting through the image
centre (actor centred in the frame) make step 3 singular. The report gives first-order standard deviations of
f (px), R (degrees) and t (mm) per pixel of 2D noise so the user can judge; more ``joints`` (all T-pose joints
lie on z = 0), a known ``focal_px`` or ``refine`` (``cv2.solvePnP`` on R, t) reduce them.
"""
from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node, optional
from ..camera import Camera
from ..ports import BODY, CAMERA, TRACKS2D, report_port
from ..skeleton import CALIBRATION_JOINTS
from ..body import DEFAULT_ANKLE_HEIGHT
from ..bundles.tracks import read_tracks
from .observations import check_joint_names, model_points, tpose_observation
from .report import calibration_report, refine_pose


class TsaiParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    n_frames: int = Field(10, ge=1, description="number of first frames (all calibration joints tracked) averaged as the T-pose")
    joints: Annotated[list[str], AfterValidator(check_joint_names)] = Field(
        list(CALIBRATION_JOINTS), min_length=5,
        description="joints used (all lie on the torso plane z = 0 in the T-pose); the seed uses the 5 torso joints, "
        "adding head, elbows, wrists, hips, knees and ankles makes the solution far less sensitive to 2D noise",
    )
    ankle_height: float = Field(
        DEFAULT_ANKLE_HEIGHT, ge=0, le=0.3, description="height of the ankle joint centres above the floor in the T-pose",
        json_schema_extra={"unit": "m"},
    )
    focal_px: float | None = Field(
        None, gt=0, description="if set, the focal length is fixed to this value and only Tz is solved in the last step",
        json_schema_extra={"unit": "px"},
    )
    refine: bool = Field(False, description="polish R, t with cv2.solvePnP (iterative) after Tsai; f is kept")


class TsaiSolution(BaseModel):
    """Result of :func:`solve_tsai_coplanar` (camera frame x right, y down, z forward)."""

    R: list[list[float]]
    T: list[float]
    f: float
    ty_sign: int
    flipped_r3_r6: bool


def _abs_ty(a1: float, a2: float, a4: float, a5: float) -> float:
    """|Ty| from C = [[a1, a2], [a4, a5]] = [[r1, r2], [r4, r5]] / Ty (Tsai's coplanar formula)."""
    sr = a1 * a1 + a2 * a2 + a4 * a4 + a5 * a5
    det = a1 * a5 - a4 * a2
    if abs(det) > 1e-12 * max(sr, 1e-300):
        ty2 = (sr - np.sqrt(max(sr * sr - 4.0 * det * det, 0.0))) / (2.0 * det * det)
    else:  # a row or column of C vanishes: Ty^2 = 1 / (sum of squares of the non-vanishing one)
        ty2 = 1.0 / max(a1 * a1 + a2 * a2, a4 * a4 + a5 * a5, a1 * a1 + a4 * a4, a2 * a2 + a5 * a5)
    return float(np.sqrt(ty2))


def _nearest_rotation(m: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(m)
    if np.linalg.det(u @ vt) < 0:
        u[:, -1] *= -1
    return u @ vt


def _solve_f_tz(R: np.ndarray, ty: float, world: np.ndarray, yd: np.ndarray, focal_px: float | None) -> tuple[float, float]:
    """Step 6: f and Tz from (y_i, -Yd_i)(f, Tz)^T = w_i Yd_i (least squares), or Tz alone when f is given."""
    y = world @ R[1] + ty
    w = world @ R[2]
    if focal_px is not None:  # -Yd_i Tz = w_i Yd_i - f y_i
        return float(focal_px), float(np.dot(-yd, w * yd - focal_px * y) / np.dot(yd, yd))
    sol, *_ = np.linalg.lstsq(np.stack([y, -yd], axis=1), w * yd, rcond=None)
    return float(sol[0]), float(sol[1])


def solve_tsai_coplanar(image_xy: np.ndarray, world_xy: np.ndarray, focal_px: float | None = None) -> TsaiSolution:
    """Coplanar Tsai calibration (steps 3-6 of the module docstring).

    ``image_xy`` (n, 2) pixels relative to the image centre (x right, y down); ``world_xy`` (n, 2) metres,
    the points' (Xw, Yw) on the plane Zw = 0; n >= 5. ``focal_px`` fixes f. Returns R (world -> camera),
    T (metres) and f (pixels) with Xc = R Xw + T. Raises ``ValueError`` for a degenerate configuration.
    """
    image_xy = np.asarray(image_xy, dtype=np.float64)
    world_xy = np.asarray(world_xy, dtype=np.float64)
    xd, yd = image_xy[:, 0], image_xy[:, 1]
    xw, yw = world_xy[:, 0], world_xy[:, 1]
    M = np.stack([yd * xw, yd * yw, yd, -xd * xw, -xd * yw], axis=1)
    Mn = M / np.linalg.norm(M, axis=0).clip(1e-300)
    sv = np.linalg.svd(Mn, compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise ValueError(
            "the radial-alignment system is singular: the points on one line (neck, chest, hips) project onto a line "
            "through the image centre, so the 5-point method cannot separate the unknowns"
        )
    a, *_ = np.linalg.lstsq(M, xd, rcond=None)
    a1, a2, a3, a4, a5 = (float(v) for v in a)

    ty = _abs_ty(a1, a2, a4, a5)
    far = int(np.argmax(xd * xd + yd * yd))
    x_far = (a1 * xw[far] + a2 * yw[far] + a3) * ty
    y_far = (a4 * xw[far] + a5 * yw[far] + 1.0) * ty
    ty_sign = 1 if x_far * xd[far] + y_far * yd[far] > 0 else -1
    ty *= ty_sign
    r1, r2, tx, r4, r5 = a1 * ty, a2 * ty, a3 * ty, a4 * ty, a5 * ty

    r3 = float(np.sqrt(max(1.0 - r1 * r1 - r2 * r2, 0.0)))
    r6 = float(-np.sign(r1 * r4 + r2 * r5) * np.sqrt(max(1.0 - r4 * r4 - r5 * r5, 0.0)))
    world = np.stack([xw, yw, np.zeros_like(xw)], axis=1)
    flipped = False
    for attempt in range(2):
        row1, row2 = np.array([r1, r2, r3]), np.array([r4, r5, r6])
        R = _nearest_rotation(np.stack([row1, row2, np.cross(row1, row2)]))
        f, tz = _solve_f_tz(R, ty, world, yd, focal_px)
        # with f fixed it cannot turn negative: the wrong sign then shows as points behind the camera
        wrong = f < 0 if focal_px is None else float(np.mean(world @ R[2])) + tz < 0
        if not wrong or attempt == 1:
            break
        r3, r6, flipped = -r3, -r6, True
    if not np.isfinite(f) or f <= 0:
        raise ValueError(f"no positive focal length (f = {f:.3g} px): the points do not look like a perspective view of the model")
    return TsaiSolution(R=R.tolist(), T=[tx, ty, tz], f=f, ty_sign=ty_sign, flipped_r3_r6=flipped)


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    c = (np.trace(np.asarray(Ra).T @ np.asarray(Rb)) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def tsai_sensitivity(image_xy: np.ndarray, world_xy: np.ndarray, sol: TsaiSolution, focal_px: float | None = None) -> dict:
    """First-order standard deviations of the solution per pixel of i.i.d. 2D noise (finite differences over
    every image coordinate): focal length (px), rotation (degrees), translation (mm). Large values mean the
    view is close to a degenerate one (torso parallel to the image, spine through the image centre)."""
    image_xy = np.asarray(image_xy, dtype=np.float64)
    R0, T0 = np.array(sol.R), np.array(sol.T)
    h = 1e-3
    df, drot, dt = [], [], []
    for idx in np.ndindex(image_xy.shape):
        moved = image_xy.copy()
        moved[idx] += h
        try:
            s = solve_tsai_coplanar(moved, world_xy, focal_px)
        except ValueError:
            return {"focal_sd_px_per_px": float("inf"), "rotation_sd_deg_per_px": float("inf"), "translation_sd_mm_per_px": float("inf")}
        df.append((s.f - sol.f) / h)
        drot.append(rotation_angle_deg(np.array(s.R), R0) / h)
        dt.append(np.linalg.norm(np.array(s.T) - T0) * 1000.0 / h)
    rss = lambda v: float(np.sqrt(np.sum(np.square(v))))  # noqa: E731
    return {"focal_sd_px_per_px": rss(df), "rotation_sd_deg_per_px": rss(drot), "translation_sd_mm_per_px": rss(dt)}


@node(
    "calibrate.tsai_coplanar",
    version=1,
    inputs={"tracks": TRACKS2D, "body": optional(BODY, "bone lengths; defaults if absent")},
    outputs={"camera": CAMERA, "report": report_port("reprojection errors (px), focal length, sensitivity, camera position")},
    params=TsaiParams,
)
def tsai_coplanar(ctx, tracks, body):
    """Camera from the T-pose torso by the seed's coplanar 5-point Tsai method (distortion ignored)."""
    p: TsaiParams = ctx.params
    tr = read_tracks(tracks)
    image, used = tpose_observation(tr, p.joints, p.n_frames)
    world = model_points(body, p.ankle_height, p.joints)
    rel = image - tr.centre
    try:
        sol = solve_tsai_coplanar(rel, world[:, :2], p.focal_px)
    except ValueError as e:
        raise NodeError(
            f"Tsai calibration failed on the T-pose of frames {used.tolist()}: {e}",
            hint="the take must start with a T-pose facing the camera with the calibration joints tracked; if the actor "
            "stands in the image centre add joints (e.g. joints: [neck, chest, hips, left_shoulder, right_shoulder, head, "
            "left_wrist, right_wrist, left_ankle, right_ankle]) or use calibrate.pnp with a known focal length",
        ) from None
    sens = tsai_sensitivity(rel, world[:, :2], sol, p.focal_px)
    cx, cy = tr.centre
    K = np.array([[sol.f, 0.0, cx], [0.0, sol.f, cy], [0.0, 0.0, 1.0]])
    R, t = np.array(sol.R), np.array(sol.T)
    if p.refine:
        R, t = refine_pose(K, R, t, world, image)
    cam = Camera(K=K, R=R, t=t, width=tr.width, height=tr.height)
    extra = {"method": "tsai_coplanar", "ty_sign": sol.ty_sign, "flipped_r3_r6": sol.flipped_r3_r6, "refined": p.refine}
    extra.update(sens)
    if sens["rotation_sd_deg_per_px"] > 1.0 or sens["focal_sd_px_per_px"] > 0.05 * sol.f:
        extra["warning"] = (
            "the view is close to degenerate for coplanar Tsai (torso nearly parallel to the image or spine through the "
            "image centre): small 2D errors move the camera a lot; use more joints, a known focal_px, or calibrate.pnp"
        )
        ctx.warn(extra["warning"])  # reaches manifest.json, metrics.json and the summary
    return {"camera": cam.to_model(), "report": calibration_report(cam, world, image, used, extra, p.joints)}
