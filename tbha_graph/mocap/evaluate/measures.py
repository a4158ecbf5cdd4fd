"""Accuracy and quality measures of 3D/2D joint data: small pure numpy functions, vectorised over frames.

Conventions: positions ``(n_frames, J, 3)`` metres (any one frame for both arguments), pixels
``(n_frames, J, 2)``; missing values are NaN and are ignored by every reduction (a reduction over no
values gives NaN). Errors are returned in the input's units (metres, pixels); callers convert to mm.

Alignment (:func:`similarity_fit`) is Umeyama's least-squares similarity (1991): find ``s, R, t`` that
minimise ``sum_i w_i |dst_i - (s R src_i + t)|^2`` with ``R`` a proper rotation (det +1); with
``scale=False`` it is the rigid (Kabsch) fit, ``s = 1``. Leading axes batch independent fits, so one
call aligns every frame separately (PA-MPJPE) or, after reshaping to one batch, a whole clip at once.
"""
from __future__ import annotations

import numpy as np

from ..rigid import procrustes

from ..skeleton import PARENTS

ALIGNMENTS = ("similarity", "rigid", "none")


def _nanmean(x: np.ndarray, axis=None) -> np.ndarray | float:
    """``np.nanmean`` (the same figures) without its "Mean of empty slice" warning: a slice with no values
    gives NaN. Sum of the non-NaN values over their count, 0 / 0 silenced by :class:`np.errstate` (per thread
    / context); ``warnings.catch_warnings`` is process-wide and would touch the filters of nodes that run
    in other threads (``tbha-run --jobs``)."""
    x = np.asarray(x, dtype=np.float64)
    ok = ~np.isnan(x)
    with np.errstate(invalid="ignore"):
        return np.sum(np.where(ok, x, 0.0), axis=axis) / np.sum(ok, axis=axis, dtype=np.intp)


def nan_percentile(x: np.ndarray, q: float) -> float:
    """The ``q``-th percentile of the finite values of ``x`` (NaN when there are none)."""
    v = np.asarray(x, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.percentile(v, q)) if v.size else float("nan")


def nan_mean(x: np.ndarray) -> float:
    """Mean of the finite values of ``x`` (NaN when there are none)."""
    v = np.asarray(x, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def frame_mean(errors: np.ndarray) -> np.ndarray:
    """Per-frame mean ``(n,)`` of ``(n, J)`` errors over the finite joints of each frame (NaN if none)."""
    return np.asarray(_nanmean(np.asarray(errors, dtype=np.float64), axis=1), dtype=np.float64)


def joint_mean(errors: np.ndarray) -> np.ndarray:
    """Per-joint mean ``(J,)`` of ``(n, J)`` errors over the finite frames of each joint (NaN if none)."""
    return np.asarray(_nanmean(np.asarray(errors, dtype=np.float64), axis=0), dtype=np.float64)


def joint_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance between matching points: ``(..., J, D)`` x2 -> ``(..., J)`` (NaN stays NaN)."""
    return np.linalg.norm(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64), axis=-1)


def root_relative(joints: np.ndarray, root: int = 0) -> np.ndarray:
    """Positions relative to the root joint of each frame: ``(..., J, 3)`` -> ``(..., J, 3)``."""
    j = np.asarray(joints, dtype=np.float64)
    return j - j[..., root : root + 1, :]


# ---------------------------------------------------------------------------------------------------
# alignment
# ---------------------------------------------------------------------------------------------------
def similarity_fit(src: np.ndarray, dst: np.ndarray, *, scale: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``dst ~ s * R @ src + t`` (Umeyama), batched over leading axes.

    ``src``, ``dst``: ``(..., m, 3)``; points where either is NaN are left out of the fit.
    Returns ``s`` ``(...)``, ``R`` ``(..., 3, 3)`` (det +1), ``t`` ``(..., 3)``. A batch with fewer than
    3 usable points, or all points at one place, gives NaN.
    """
    src, dst = np.broadcast_arrays(np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64))
    w = (np.isfinite(src).all(-1) & np.isfinite(dst).all(-1)).astype(np.float64)  # (..., m)
    count = w.sum(-1)  # (...)
    src0 = np.where(w[..., None] > 0, src, 0.0)
    dst0 = np.where(w[..., None] > 0, dst, 0.0)
    s, R, t = procrustes(src0, dst0, w, scale=scale)
    mu_s = np.einsum("...m,...mi->...i", w, src0) / np.maximum(count, 1.0)[..., None]
    spread = np.einsum("...m,...mi->...", w, (src0 - mu_s[..., None, :]) ** 2)
    bad = (count < 3) | ~(spread > 0)
    s = np.where(bad, np.nan, s)
    R = np.where(bad[..., None, None], np.nan, R)
    t = np.where(bad[..., None], np.nan, t)
    return s, R, t


def apply_similarity(points: np.ndarray, s: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``s * R @ p + t`` for points ``(..., m, 3)`` with ``s`` ``(...)``, ``R`` ``(..., 3, 3)``, ``t`` ``(..., 3)``."""
    p = np.asarray(points, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    return s[..., None, None] * np.einsum("...ij,...mj->...mi", R, p) + np.asarray(t)[..., None, :]


def align_clip(pred: np.ndarray, truth: np.ndarray, mode: str = "similarity") -> tuple[np.ndarray, dict]:
    """Align a whole clip ``pred`` ``(n, J, 3)`` to ``truth`` ``(n, J, 3)`` with ONE transform fitted to
    all frames and joints together (so the motion's own drift, lean and size errors remain visible).

    ``mode``: ``"similarity"`` (rotation, translation, uniform scale), ``"rigid"`` (rotation and
    translation) or ``"none"``. Returns the aligned ``pred`` and ``{"scale", "rotation_deg",
    "translation_m"}`` describing the transform (how far the calibrated world frame was off).
    """
    if mode not in ALIGNMENTS:
        raise ValueError(f"unknown alignment {mode!r}: use one of {ALIGNMENTS}")
    pred = np.asarray(pred, dtype=np.float64)
    if mode == "none":
        return pred.copy(), {"scale": 1.0, "rotation_deg": 0.0, "translation_m": 0.0}
    s, R, t = similarity_fit(pred.reshape(1, -1, 3), np.asarray(truth, dtype=np.float64).reshape(1, -1, 3), scale=mode == "similarity")
    aligned = apply_similarity(pred.reshape(1, -1, 3), s, R, t).reshape(pred.shape)
    cos = np.clip((np.trace(R[0]) - 1.0) / 2.0, -1.0, 1.0)
    return aligned, {"scale": float(s[0]), "rotation_deg": float(np.degrees(np.arccos(cos))), "translation_m": float(np.linalg.norm(t[0]))}


def procrustes_per_frame(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``pred`` ``(n, J, 3)`` aligned to ``truth`` frame by frame with a similarity (the PA-MPJPE alignment)."""
    s, R, t = similarity_fit(pred, truth, scale=True)
    return apply_similarity(pred, s, R, t)


# ---------------------------------------------------------------------------------------------------
# temporal and skeletal quality
# ---------------------------------------------------------------------------------------------------
def acceleration(joints: np.ndarray, fps: float) -> np.ndarray:
    """Second difference times fps^2: ``(n, J, 3)`` metres -> ``(n - 2, J, 3)`` m/s^2."""
    return np.diff(np.asarray(joints, dtype=np.float64), n=2, axis=0) * float(fps) ** 2


def jitter(joints: np.ndarray, fps: float) -> float:
    """WHAM's jitter: mean over frames and joints of |third difference| x fps^3, m/s^3 (NaN if n < 4)."""
    j = np.asarray(joints, dtype=np.float64)
    if j.shape[0] < 4:
        return float("nan")
    return nan_mean(np.linalg.norm(np.diff(j, n=3, axis=0), axis=-1)) * float(fps) ** 3


def accel_error(pred: np.ndarray, truth: np.ndarray, fps: float) -> float:
    """Mean |acceleration(pred) - acceleration(truth)| over frames and joints, m/s^2 (NaN if n < 3)."""
    if np.shape(pred)[0] < 3:
        return float("nan")
    return nan_mean(joint_distances(acceleration(pred, fps), acceleration(truth, fps)))


def bone_lengths(joints: np.ndarray) -> np.ndarray:
    """Length of each bone per frame: ``(n, J, 3)`` -> ``(n, J - 1)`` metres (bone ``k`` ends at joint ``k + 1``)."""
    j = np.asarray(joints, dtype=np.float64)
    return np.linalg.norm(j[:, 1:] - j[:, PARENTS[1:]], axis=-1)


def bone_length_cv(joints: np.ndarray) -> np.ndarray:
    """Coefficient of variation (std / mean over frames) of each bone's length, ``(J - 1,)`` (unitless)."""
    L = bone_lengths(joints)
    mean = _nanmean(L, axis=0)
    ok = ~np.isnan(L)  # np.nanstd's figures without its warnings: NaN for a bone never seen
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(ok, L - mean, 0.0)
        std = np.sqrt(np.sum(d * d, axis=0) / np.sum(ok, axis=0, dtype=np.intp))
        return np.where(mean > 0, std / mean, np.nan)


def joint_angles(joints: np.ndarray) -> np.ndarray:
    """Angle at each joint between its parent bone and its own bone, ``(n, J, 3)`` -> ``(n, K)`` degrees, for the
    ``K`` joints whose parent is not the root (0: straight on, 180: folded back): elbow and knee flexion, the
    shoulder's and hip's angle to the girdle, the neck's and head's bend. Needs no alignment."""
    j = np.asarray(joints, dtype=np.float64)
    kids = np.array([k for k in range(1, j.shape[1]) if PARENTS[k] > 0])
    a = j[:, kids] - j[:, PARENTS[kids]]
    b = j[:, PARENTS[kids]] - j[:, PARENTS[PARENTS[kids]]]
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def joint_angle_error(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``|angle(pred) - angle(truth)|`` per frame and joint (:func:`joint_angles`), ``(n, K)`` degrees."""
    return np.abs(joint_angles(pred) - joint_angles(truth))


# ---------------------------------------------------------------------------------------------------
# image-space errors
# ---------------------------------------------------------------------------------------------------
def masked_distances(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Distances ``(n, J)`` between ``a`` and ``b`` ``(n, J, D)`` where ``mask`` ``(n, J)`` is True, NaN elsewhere."""
    d = joint_distances(a, b)
    return np.where(np.asarray(mask, dtype=bool), d, np.nan)


def reprojection_errors(joints_world: np.ndarray, camera, points: np.ndarray, tracked: np.ndarray) -> np.ndarray:
    """Pixel distance ``(n, J)`` between the 3D joints projected with ``camera`` (a
    :class:`~tbha_graph.mocap.camera.Camera`) and the tracked 2D ``points`` ``(n, J, 2)``; NaN where not
    ``tracked`` or where a joint lies behind the camera."""
    j = np.asarray(joints_world, dtype=np.float64)
    front = camera.to_camera(j)[..., 2] > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = camera.project(j)
    return masked_distances(proj, points, np.asarray(tracked, dtype=bool) & front)


def lag_frames(pred: np.ndarray, truth: np.ndarray, max_shift: int = 15) -> int:
    """Delay of ``pred`` behind ``truth`` in frames (positive = late), both ``(n, J, 3)``: the shift that
    maximises the correlation of their velocities, summed over joints and axes. NaN samples count as 0."""
    vp = np.nan_to_num(np.diff(np.asarray(pred, dtype=np.float64), axis=0)).reshape(len(pred) - 1, -1)
    vt = np.nan_to_num(np.diff(np.asarray(truth, dtype=np.float64), axis=0)).reshape(len(truth) - 1, -1)
    n = vp.shape[0]
    best, best_score = 0, -np.inf
    for s in range(-min(max_shift, n - 1), min(max_shift, n - 1) + 1):
        a = vp[max(s, 0) : n + min(s, 0)]
        b = vt[max(-s, 0) : n - max(s, 0)]
        score = float(np.sum(a * b)) / max(len(a), 1)
        if score > best_score:
            best, best_score = s, score
    return best
