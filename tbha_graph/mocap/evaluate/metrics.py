"""``evaluate.metrics``: one flat dict of quality and accuracy figures for a capture, plus per-frame errors.

Figures that need no ground truth (available for a user's own video):

* ``frames``, ``video_fps`` (of the 2D tracks, i.e. of the video), ``tracked_pct``: % of the (frame,
  joint) pairs of the tracks flagged ``tracked`` (16 joints: the head's dark hair counts as its patch).
* ``reprojection_px_median`` / ``_p95``: the final 3D motion's joint centres projected with the camera vs the
  tracked 2D points (tracked pairs only), pixels (a suit's patches sit a few px off their joints; the solver's
  fit of the points as it models them is ``fit_px_median``, passed on from its report via ``extra``).
* ``bone_length_cv_pct``: mean over the 15 bones of std/mean of the bone's length over frames, %.
* ``jitter_m_s3``: WHAM's jitter, mean |third difference| x fps^3 over frames and joints, m/s^3
  (``raw_jitter_m_s3`` for ``raw_motion``, the motion before filtering, when connected).

With ground truth (``truth`` connected and not ``{}``):

* ``mpjpe_mm``: mean joint position error in the world frame after aligning the WHOLE clip to the truth
  with ONE transform fitted over all frames and joints (``alignment`` param: ``rigid`` = rotation +
  translation (default: a wrong scale, i.e. a wrong camera, stays in the figure), ``similarity`` = Umeyama
  rotation + translation + uniform scale, ``none``). ``root_mpjpe_mm``: the same for the root (hips) alone,
  the global trajectory's error. The
  calibrated world frame is the calibration's own choice, so some alignment is needed; one transform for
  the clip keeps drift, lean and per-frame errors in the figure. The fitted transform is reported as
  ``alignment_scale``, ``alignment_rotation_deg``, ``alignment_translation_m``.
* ``mpjpe_root_mm``: root-relative (hips subtracted per frame), no alignment: meaningful when the
  calibrated world axes match the truth's (e.g. a known camera); includes the root (error 0).
* ``pa_mpjpe_mm``: each frame aligned separately with a similarity (Procrustes), root-free shape error.
* ``joint_angle_err_deg``: mean |angle - truth's angle| over frames and the joints whose parent is not the
  root, the angle at a joint being that between its parent bone and its own (elbow and knee flexion, the
  limbs' angle to the girdles, the neck's and head's bend); no alignment.
* ``error_2d_px_median`` / ``_p95``: the tracked 2D points vs the truth's ``joints2d`` (rescaled to the
  tracks' image size), for joints the truth marks visible; ``placed_2d_px_median`` / ``_p95``: the same for
  the points the tracker placed without seeing them (untracked; the solver gives them no weight), so a
  guess for a patch seen only as a sliver does not read as a tracking error.
* ``accel_error_m_s2``: mean |acceleration - truth's acceleration| (second difference x fps^2), world
  frame after the clip alignment; ``truth_jitter_m_s3``: the real motion's own jitter, for reference.
* ``raw_mpjpe_mm``, ``raw_accel_error_m_s2`` for ``raw_motion`` (same alignment, fitted separately).
* ``per_joint_mpjpe_mm``: nested ``{joint name: mm}`` (aligned, as ``mpjpe_mm``).

``doubtful_ranges``: ``[[first, last, reason], ...]`` frames whose labelling or result is doubtful
(:mod:`tbha_graph.mocap.evaluate.doubtful`); the ``errors`` bundle gets the per-frame bits as ``doubtful``.

Floor and camera (no ground truth needed): ``floor_penetration_mm`` (worst ankle below its resting height
above the floor y = 0), ``foot_skate_mm`` (mean horizontal movement per frame of a planted ankle),
``export_floor_penetration_mm`` and ``export_foot_skate_mm`` (the same for the exported joints, when given),
``focal_px``; with a truth camera ``focal_err_pct`` and ``camera_height_err_m``.

A figure that cannot be computed (e.g. jitter of a clip shorter than 4 frames) is ``null``.

Output ``errors`` (per frame, NaN where unavailable): ``mpjpe_mm``, ``mpjpe_root_mm``, ``pa_mpjpe_mm``,
``error_2d_px`` (tracked points), ``placed_2d_px`` (untracked points), ``reprojection_px`` (each ``(n_frames,)``,
mean over the frame's joints), ``fps`` ().
"""
from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node, optional
from ...core.types import Json
from .verdict import verdict
from ..bundles.truth import check_ground_truth, truth_joints2d, truth_visibility
from ..ports import CAMERA, ERRORS, JOINTS3D_EXPORT, METRICS, MOTION, REPORT, TRACKS2D, TRUTH
from ..body import DEFAULT_ANKLE_HEIGHT
from ..skeleton import JOINT_NAMES, N_JOINTS, PATCHED_JOINTS
from . import measures as m
from .doubtful import doubtful_bits, doubtful_ranges


class MetricsParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    alignment: Literal["similarity", "rigid", "none"] = Field(
        "rigid",
        description="how the motion's world frame is aligned to the truth's for mpjpe_mm: one transform for the "
                    "whole clip, 'similarity' (rotation, translation, scale), 'rigid' (no scale) or 'none'",
    )


def _figure(x: float, digits: int = 4) -> float | None:
    """A JSON-friendly figure: rounded, None for NaN/inf."""
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def _joints(bundle: dict, what: str) -> tuple[np.ndarray, float]:
    j = np.asarray(bundle["joints"], dtype=np.float64)
    fps = float(np.asarray(bundle["fps"]))
    if j.ndim != 3 or j.shape[1:] != (N_JOINTS, 3) or j.shape[0] == 0:
        raise NodeError(f"{what}: joints has shape {j.shape}, expected (n_frames > 0, {N_JOINTS}, 3)")
    if not (math.isfinite(fps) and fps > 0):
        raise NodeError(f"{what}: fps is {fps}, expected a positive number of frames per second")
    return j, fps


def _same_length(n: int, other: int, what: str) -> None:
    if other != n:
        raise NodeError(
            f"{what} has {other} frames but the motion has {n}",
            hint="evaluate the same frame range everywhere: give io.ground_truth the start/stop of io.video",
        )


def quality_figures(joints: np.ndarray, fps: float, tracks: dict, camera) -> tuple[dict, np.ndarray]:
    """Figures needing no ground truth (see module docstring) and the per-frame reprojection error (n,) px.
    The reprojection compares joint centres with tracked patch centres, so it includes the patches' offsets
    from the joints (a few px); the solver's own fit of the patches is its report's ``fit_px_median``."""
    tracked = np.asarray(tracks["tracked"], dtype=bool)
    reproj = m.reprojection_errors(joints, camera, tracks["points"], tracked)
    figures = {
        "tracked_pct": _figure(100.0 * tracked.mean()),
        "reprojection_px_median": _figure(m.nan_percentile(reproj, 50)),
        "reprojection_px_p95": _figure(m.nan_percentile(reproj, 95)),
        "bone_length_cv_pct": _figure(100.0 * m.nan_mean(m.bone_length_cv(joints))),
        "jitter_m_s3": _figure(m.jitter(joints, fps)),
    }
    return figures, m.frame_mean(reproj)


def truth_figures(joints: np.ndarray, fps: float, truth: dict, alignment: str) -> tuple[dict, dict[str, np.ndarray]]:
    """3D accuracy figures against ``truth['joints3d_world']`` and per-frame errors (mm)."""
    gt = truth["joints3d_world"]
    aligned, transform = m.align_clip(joints, gt, alignment)
    err = m.joint_distances(aligned, gt) * 1000.0  # (n, 16) mm
    err_root = m.joint_distances(m.root_relative(joints), m.root_relative(gt)) * 1000.0
    err_pa = m.joint_distances(m.procrustes_per_frame(joints, gt), gt) * 1000.0
    per_joint = m.joint_mean(err)
    figures = {
        "mpjpe_mm": _figure(m.nan_mean(err)),
        "mpjpe_alignment": alignment,
        "alignment_scale": _figure(transform["scale"]),
        "alignment_rotation_deg": _figure(transform["rotation_deg"]),
        "alignment_translation_m": _figure(transform["translation_m"]),
        "mpjpe_root_mm": _figure(m.nan_mean(err_root)),
        "pa_mpjpe_mm": _figure(m.nan_mean(err_pa)),
        "accel_error_m_s2": _figure(m.accel_error(aligned, gt, fps)),
        "root_mpjpe_mm": _figure(m.nan_mean(err[:, 0])),
        "joint_angle_err_deg": _figure(m.nan_mean(m.joint_angle_error(joints, gt))),
        "lag_ms": _figure(1000.0 * m.lag_frames(aligned, gt) / fps),
        "truth_jitter_m_s3": _figure(m.jitter(gt, fps)),
        "per_joint_mpjpe_mm": {name: _figure(v) for name, v in zip(JOINT_NAMES, per_joint)},
    }
    per_frame = {"mpjpe_mm": m.frame_mean(err), "mpjpe_root_mm": m.frame_mean(err_root), "pa_mpjpe_mm": m.frame_mean(err_pa)}
    return figures, per_frame


def floor_figures(joints: np.ndarray, fps: float, ankle_height: float = DEFAULT_ANKLE_HEIGHT) -> dict:
    """Contact with the floor (world y = 0), no ground truth needed. ``floor_penetration_mm``: how far the
    worst foot goes below the floor (the ankle joint below ``ankle_height``), 0 if never; ``foot_skate_mm``:
    mean horizontal movement per frame of an ankle while planted: within 3 cm of its resting height and
    moving under 1 cm per frame (at 30 fps; WHAM's contact rule) on both ends of the step."""
    ank = joints[:, [JOINT_NAMES.index("left_ankle"), JOINT_NAMES.index("right_ankle")]]
    height = ank[..., 1] - ankle_height
    out = {"floor_penetration_mm": _figure(max(0.0, -float(np.nanmin(height))) * 1000.0)}
    if joints.shape[0] > 1:
        step = np.linalg.norm(np.diff(ank[..., [0, 2]], axis=0), axis=-1)  # (n-1, 2) horizontal metres
        planted = (height[1:] < 0.03) & (height[:-1] < 0.03) & (step < 0.01 * 30.0 / fps)
        out["foot_skate_mm"] = _figure(float(step[planted].mean()) * 1000.0 if planted.any() else 0.0)
    return out


def camera_figures(camera, truth: dict | None) -> dict:
    """``focal_px`` of the capture's camera and, when the truth has its camera, ``focal_err_pct`` and the
    error of the camera's height above the floor ``camera_height_err_m``."""
    out = {"focal_px": _figure(float(camera.K[0, 0]), 2)}
    if truth and "K" in truth:
        f_true = float(np.asarray(truth["K"])[0, 0])
        out["focal_err_pct"] = _figure(100.0 * (float(camera.K[0, 0]) / f_true - 1.0), 3)
        if "R" in truth and "t" in truth:
            true_centre = -np.asarray(truth["R"]).T @ np.asarray(truth["t"])
            out["camera_height_err_m"] = _figure(float(camera.center[1] - true_centre[1]))
    return out


def patch_figures(joints: np.ndarray, points: np.ndarray, truth: dict, alignment: str) -> dict:
    """Figures against the patches themselves, when a render's truth has them: the tracker is asked to
    find patch centres (``patch2d``), and the seed's method reconstructs patch centres
    (``patch_centers_world``), which sit on the suit a few centimetres in front of the joint centres.
    ``tracking_2d_px_*``: tracks vs ``patch2d`` for visible patches; ``marker_mpjpe_mm``: the 3D joints
    of the patched joints vs the patch centres (same clip alignment as ``mpjpe_mm``)."""
    out: dict = {}
    idx = [JOINT_NAMES.index(j) for j in PATCHED_JOINTS]
    if "patch2d" in truth and "patch_visible" in truth:
        vis = np.asarray(truth["patch_visible"], dtype=bool)
        e = m.masked_distances(points[:, idx], np.asarray(truth["patch2d"], dtype=np.float64), vis)
        out["tracking_2d_px_median"] = _figure(m.nan_percentile(e, 50))
        out["tracking_2d_px_p95"] = _figure(m.nan_percentile(e, 95))
    if "patch_centers_world" in truth:
        gt = np.asarray(truth["patch_centers_world"], dtype=np.float64)
        aligned, _ = m.align_clip(joints[:, idx], gt, alignment)
        out["marker_mpjpe_mm"] = _figure(m.nan_mean(m.joint_distances(aligned, gt) * 1000.0))
    return out


def compute_metrics(
    motion: dict, tracks: dict, camera, truth: dict | None = None, raw_motion: dict | None = None, alignment: str = "rigid",
    exported: dict | None = None, unseen: list | None = None,
) -> tuple[dict, dict[str, np.ndarray]]:
    """The ``metrics`` dict and the ``errors`` bundle (see module docstring). ``camera`` is a
    :class:`~tbha_graph.mocap.camera.Camera`; ``truth`` ``None`` or ``{}`` means no ground truth;
    ``exported``: ``export.joints3d``'s bundle (its ``joints``: where the BVH puts every joint), scored too;
    ``unseen``: the solver's ``unseen_ranges`` (frames with nothing of the actor seen: ``not seen`` in ``doubtful_ranges``)."""
    joints, fps = _joints(motion, "motion")
    n = joints.shape[0]
    points = np.asarray(tracks["points"], dtype=np.float64)
    if points.ndim == 3:
        _same_length(n, points.shape[0], "the 2D tracks")
    if points.shape != (n, N_JOINTS, 2) or np.shape(tracks["tracked"]) != (n, N_JOINTS):
        raise NodeError(f"tracks: points {points.shape} / tracked {np.shape(tracks['tracked'])}, expected ({n}, {N_JOINTS}, 2) / ({n}, {N_JOINTS})")
    metrics: dict = {"frames": int(n), "video_fps": _figure(float(np.asarray(tracks.get("fps", fps))))}
    quality, reproj = quality_figures(joints, fps, tracks, camera)
    metrics.update(quality)
    metrics.update(floor_figures(joints, fps))
    out = None
    if exported is not None:  # what the user gets: the BVH's joints (rotations fitted, hinge limits, FK)
        out = np.asarray(exported["joints"], dtype=np.float64)
        _same_length(n, out.shape[0], "the exported joints")
        metrics.update({f"export_{k}": v for k, v in floor_figures(out, fps).items()})
    metrics.update(camera_figures(camera, truth if truth else None))
    if "inferred" in motion:  # samples filled by filter.fill_gaps; the rest of the untracked ones are missing
        inferred = np.asarray(motion["inferred"], dtype=bool)
        tracked3d = np.asarray(motion.get("tracked", tracks["tracked"]), dtype=bool)
        metrics["inferred_pct"] = _figure(100.0 * inferred.mean())
        metrics["missing_pct"] = _figure(100.0 * (~(tracked3d | inferred)).mean())
    nan = np.full(n, np.nan)
    errors = {"mpjpe_mm": nan, "mpjpe_root_mm": nan, "pa_mpjpe_mm": nan, "error_2d_px": nan, "placed_2d_px": nan,
              "reprojection_px": reproj,
              "fps": np.asarray(fps, dtype=np.float64)}
    doubt = doubtful_bits(n, tracks, motion, reproj, unseen)  # issue 13: frames whose labelling/result is doubtful
    metrics["doubtful_ranges"] = doubtful_ranges(doubt)
    errors["doubtful"] = doubt.astype(np.float64)

    raw = None
    if raw_motion is not None:
        raw, _ = _joints(raw_motion, "raw_motion")
        _same_length(n, raw.shape[0], "raw_motion")
        metrics["raw_jitter_m_s3"] = _figure(m.jitter(raw, fps))

    if truth:
        truth = check_ground_truth(truth, "truth")
        _same_length(n, truth["joints3d_world"].shape[0], "the ground truth")
        figures, per_frame = truth_figures(joints, fps, truth, alignment)
        errors.update(per_frame)
        per_joint = figures.pop("per_joint_mpjpe_mm")
        metrics.update(figures)
        gt2d = truth_joints2d(truth, int(tracks["width"]) if "width" in tracks else None,
                              int(tracks["height"]) if "height" in tracks else None)
        if gt2d is not None:
            seen = truth_visibility(truth)
            tracked = np.asarray(tracks["tracked"], dtype=bool)
            for name, which in (("error_2d_px", tracked), ("placed_2d_px", ~tracked)):
                e2d = m.masked_distances(points, gt2d, seen & which)
                metrics[f"{name}_median"] = _figure(m.nan_percentile(e2d, 50))
                metrics[f"{name}_p95"] = _figure(m.nan_percentile(e2d, 95))
                errors[name] = m.frame_mean(e2d)
        metrics.update(patch_figures(joints, points, truth, alignment))
        if raw is not None:
            raw_figures, _ = truth_figures(raw, fps, truth, alignment)
            metrics["raw_mpjpe_mm"] = raw_figures["mpjpe_mm"]
            metrics["raw_accel_error_m_s2"] = raw_figures["accel_error_m_s2"]
        if out is not None:
            export_figures, _ = truth_figures(out, fps, truth, alignment)
            metrics["export_mpjpe_mm"] = export_figures["mpjpe_mm"]
            metrics["export_pa_mpjpe_mm"] = export_figures["pa_mpjpe_mm"]
        metrics["per_joint_mpjpe_mm"] = per_joint
    return metrics, errors


@node(
    "evaluate.metrics",
    version=8,
    inputs={
        "motion": MOTION,
        "tracks": TRACKS2D,
        "camera": CAMERA,
        "truth": optional(TRUTH, "ground truth (io.ground_truth); {} or unconnected = none"),
        "raw_motion": optional(MOTION, "the motion before filtering, to report what the filter changed"),
        "exported": optional(JOINTS3D_EXPORT, "export.joints3d's joints (where the BVH puts them), scored as "
                                              "export_mpjpe_mm / export_pa_mpjpe_mm beside the solver's motion"),
        "extra": optional(Json(), "figures from other nodes' reports (e.g. filter.foot_contact's foot sliding), "
                                  "merged into metrics: their top-level numbers and strings"),
        "camera_motion": optional(REPORT, "calibrate.camera_motion's report: camera_shift_px and camera_moved join the "
                                          "metrics"),
    },
    outputs={"metrics": METRICS, "errors": ERRORS},
    params=MetricsParams,
)
def metrics(ctx, motion, tracks, camera, truth, raw_motion, extra, exported, camera_motion):
    """Quality figures of a capture (reprojection, bone-length stability, jitter) and, with ground
    truth, its accuracy (MPJPE, PA-MPJPE, 2D error, acceleration error); per-frame errors for plots.

    Output ``metrics``: flat dict (units in the key names: _mm, _px, _pct, _m_s3...), plus the nested
    ``per_joint_mpjpe_mm``. Output ``errors``: per-frame arrays (see tbha_graph.mocap.evaluate.metrics).
    """
    unseen = extra.get("unseen_ranges") if isinstance(extra, dict) else None  # the solver's frames with nothing seen
    result, errors = compute_metrics(motion, tracks, camera.camera(), truth, raw_motion, ctx.params.alignment, exported,
                                     unseen if isinstance(unseen, list) else None)
    if isinstance(extra, dict):
        result.update({k: v for k, v in extra.items() if isinstance(v, (int, float, str, bool)) and k not in result})
        notes = [w for w in extra.get("warnings", []) if isinstance(w, str)]
        if notes:  # warnings of the node that made the report reach the metrics (and the summary)
            result["warnings"] = list(result.get("warnings", [])) + [w for w in notes if w not in result.get("warnings", [])]
    if isinstance(camera_motion, dict):  # the camera's own motion (is it still?), when measured
        result.update({k: camera_motion.get(k) for k in ("camera_shift_px", "camera_moved") if k in camera_motion})
    result.setdefault("warnings", [])  # always there (docs/metrics.md): an empty list when no node warned
    result["verdict"], result["verdict_reasons"] = verdict(result)  # ok | doubtful | failed (evaluate/verdict.py)
    return {"metrics": result, "errors": errors}
