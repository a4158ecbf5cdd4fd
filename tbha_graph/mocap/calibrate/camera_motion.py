"""``calibrate.camera_motion``: did the camera stay still? The background's motion over the take, measured.

Everything after tracking assumes one camera that does not move (a tripod): one focal length, one floor, one
pose for the whole take. A phone held in the hand, a camera bumped or panned, or a zoom breaks that without a
sign in the capture's own figures (the solver fits the 2D all the same: the camera's motion becomes the actor's).
This node measures it from the background:

1. Frames sampled every ``step`` (at most ``max_samples``, and the last), greyscale, downscaled to at most
   ``max_width`` px wide.
2. Corners (:func:`cv2.goodFeaturesToTrack`, cell by cell of a 4 x 4 grid) on the first sampled frame, away from the actor: outside the box
   where the actor may be (:func:`..bundles.tracks.body_boxes` from the tracks, when connected), spread over a
   quarter of the image's width or height at least (:data:`MIN_SPREAD`).
3. Each later sample: the corners followed from the first frame (pyramidal Lucas-Kanade,
   :func:`cv2.calcOpticalFlowPyrLK`, started where the previous sample's motion puts them and checked
   backwards: a corner that does not come back within ``0.5`` px is dropped), those on the actor's box in that
   frame dropped, and a similarity (rotation, scale, shift) fitted with RANSAC
   (:func:`cv2.estimateAffinePartial2D`; its inliers spread as in 2). The frame's **shift** is the largest displacement it gives the
   image's four corners, in pixels of the video's frames.

The camera **moved** when at least two samples shift by more than ``threshold_px``: a warning naming how far and
when. Too few corners (a plain background) or too few followed on some frame: those frames are not judged (the
report says how many; no warning on that alone).

Output ``report``: ``camera_shift_px`` (the largest shift, full-resolution px; NaN when nothing could be
judged), ``camera_shift_frame``, ``camera_moved`` (bool), ``camera_motion_frames_judged`` / ``_sampled``,
``camera_motion_corners``, and per sample ``frames`` / ``shift_px`` (lists).
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.node import node, optional
from ..bundles.tracks import body_boxes, read_tracks
from ..io.video import iter_frames_at
from ..ports import REPORT, TRACKS2D, VIDEO, VideoClip
from ..runs import runs_of

#: fewest corners the first frame must give, and fewest followed and kept by RANSAC on a frame, to judge it
MIN_CORNERS = 12
#: a corner followed to a frame and back must land this close to where it started (analysed px)
BACK_PX = 0.5
#: the corners that judge a frame must spread over at least this fraction of the image's width or height (a few
#: corners on one small thing, e.g. a part of the actor the tracks leave out, are not the background)
MIN_SPREAD = 0.25
#: corners are found in each cell of a GRID x GRID grid (:func:`grid_corners`)
GRID = 4
#: the actor's box (the tracks' points) grown by this fraction of the body's height on every side
ACTOR_MARGIN = 0.15


class CameraMotionParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    step: int = Field(5, ge=1, le=100, description="frames between the samples compared with the first (more on a take "
                      "longer than max_samples of them)", json_schema_extra={"unit": "frame"})
    max_samples: int = Field(200, ge=10, description="frames compared with the first at most (spread evenly)")
    threshold_px: float = Field(2.0, gt=0, description="a shift of the background beyond this (on two samples or more) "
                                "is a moving camera", json_schema_extra={"unit": "px"})
    max_width: int = Field(640, ge=64, description="frames analysed at most this wide (downscaled)", json_schema_extra={"unit": "px"})
    max_corners: int = Field(200, ge=MIN_CORNERS, description="background corners followed")


def _inside(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """``(k,)`` bool: points ``(k, 2)`` inside ``box`` ``[x0, y0, x1, y1]`` (none when the box is NaN)."""
    if not np.isfinite(box).all():
        return np.zeros(len(points), bool)
    return (points[:, 0] >= box[0]) & (points[:, 0] <= box[2]) & (points[:, 1] >= box[1]) & (points[:, 1] <= box[3])


def grid_corners(grey: np.ndarray, max_corners: int, cells: int = GRID) -> np.ndarray:
    """``(k, 2)`` float32 corners (:func:`cv2.goodFeaturesToTrack`) found cell by cell of a ``cells`` x ``cells`` grid,
    up to ``max_corners / cells²`` in each, each cell's quality relative to its own strongest corner: the
    background's corners count even where something else in the picture (text, the actor) has far stronger ones."""
    h, w = grey.shape
    per = max(1, max_corners // cells**2)
    out = []
    for i in range(cells):
        for j in range(cells):
            y0, y1, x0, x1 = h * i // cells, h * (i + 1) // cells, w * j // cells, w * (j + 1) // cells
            found = cv2.goodFeaturesToTrack(grey[y0:y1, x0:x1], maxCorners=per, qualityLevel=0.05, minDistance=8, blockSize=7)
            if found is not None:
                out.append(found.reshape(-1, 2) + np.array([x0, y0], np.float32))
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, 2), np.float32)


def spread(points: np.ndarray, size: tuple[int, int]) -> bool:
    """Do ``points`` ``(k, 2)`` spread over :data:`MIN_SPREAD` of the image's width or height ``size`` (w, h)?"""
    extent = np.ptp(points, axis=0) / np.asarray(size, float)
    return bool(extent.max() >= MIN_SPREAD)


def corner_shift(A: np.ndarray, width: float, height: float) -> float:
    """Largest displacement ``(px)`` the 2x3 similarity ``A`` gives the corners of a ``width`` x ``height`` image."""
    c = np.array([[0, 0], [width, 0], [0, height], [width, height]], float)
    return float(np.linalg.norm(c @ A[:, :2].T + A[:, 2] - c, axis=1).max())


def background_shifts(clip: VideoClip, boxes: np.ndarray | None, p: CameraMotionParams) -> dict:
    """Per sampled frame, how far the background moved from the first sampled frame's (see the module).
    ``boxes`` ``(n_frames, 4)`` full-resolution px where the actor may be (NaN rows: unknown), or None."""
    step = max(p.step, math.ceil((clip.stop - clip.start) / p.max_samples))
    picks = list(range(clip.start, clip.stop, step))
    if picks[-1] != clip.stop - 1:
        picks.append(clip.stop - 1)
    s = min(1.0, p.max_width / clip.width)
    size = (max(1, round(clip.width * s)), max(1, round(clip.height * s)))
    box_of = (lambda i: boxes[i - clip.start] * s) if boxes is not None else (lambda i: np.full(4, np.nan))
    lk = dict(winSize=(15, 15), maxLevel=2, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
    ref = pts0 = None
    A = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    frames, shifts = [], []
    for index, frame in iter_frames_at(clip, picks):
        g = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        if s < 1.0:
            g = cv2.resize(g, size, interpolation=cv2.INTER_AREA)
        if ref is None:
            pts0 = grid_corners(g, p.max_corners)
            pts0 = pts0[~_inside(pts0, box_of(index))]
            ref = g
            frames.append(index)
            shifts.append(0.0)
            if len(pts0) < MIN_CORNERS or not spread(pts0, size):
                pts0 = pts0[:0]
                break
            continue
        guess = (pts0 @ A[:, :2].T + A[:, 2]).astype(np.float32)
        pts1, ok1, _ = cv2.calcOpticalFlowPyrLK(ref, g, pts0, guess.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
        back, ok2, _ = cv2.calcOpticalFlowPyrLK(g, ref, pts1, pts0.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
        good = (ok1.ravel() == 1) & (ok2.ravel() == 1) & (np.linalg.norm(back - pts0, axis=1) < BACK_PX)
        good &= ~_inside(pts1, box_of(index))
        frames.append(index)
        fit = None
        if good.sum() >= MIN_CORNERS:
            fit, inliers = cv2.estimateAffinePartial2D(pts0[good], pts1[good], method=cv2.RANSAC, ransacReprojThreshold=1.0)
            if fit is not None and (int(inliers.sum()) < MIN_CORNERS or not spread(pts0[good][inliers.ravel() == 1], size)):
                fit = None
        if fit is None:
            shifts.append(math.nan)
            continue
        A = fit
        shifts.append(corner_shift(A, size[0], size[1]) / s)
    return {"frames": frames, "shift_px": shifts, "corners": 0 if pts0 is None else int(len(pts0)), "sampled": len(picks)}


@node(
    "calibrate.camera_motion",
    version=1,
    inputs={"video": VIDEO, "tracks": optional(TRACKS2D, "where the actor is (their box is left out of the background)")},
    outputs={"report": REPORT},
    params=CameraMotionParams,
)
def camera_motion(ctx, video, tracks) -> dict:
    """Measure how far the background moves over the take (the camera must stay still); warn when it moved.

    Output ``report``: ``camera_shift_px`` (largest shift of the background from the first frame's, px of the
    video's frames), ``camera_moved``, the frames judged, and the shift per sampled frame (see the module)."""
    p: CameraMotionParams = ctx.params
    clip = VideoClip.model_validate(video) if isinstance(video, dict) else video
    boxes = None
    if tracks is not None and len(tracks):
        tr = read_tracks(tracks, "tracks")
        if len(tr.points) == clip.stop - clip.start:
            boxes = body_boxes(tr.points, tr.tracked, ACTOR_MARGIN)
    m = background_shifts(clip, boxes, p)
    shift = np.array(m["shift_px"], float)
    judged = np.isfinite(shift)
    frames = np.array(m["frames"])
    worst = float(np.nanmax(shift)) if judged.sum() > 1 else math.nan
    over = judged & (np.nan_to_num(shift) > p.threshold_px)
    moved = bool(over.sum() >= 2)
    report = {
        "camera_shift_px": round(worst, 2) if math.isfinite(worst) else None,
        "camera_shift_frame": int(frames[np.nanargmax(shift)]) if math.isfinite(worst) else None,
        "camera_moved": moved,
        "camera_motion_frames_judged": int(judged.sum()) - 1 if judged.any() else 0,
        "camera_motion_frames_sampled": int(m["sampled"]) - 1,
        "camera_motion_corners": m["corners"],
        "frames": [int(f) for f in frames],
        "shift_px": [round(float(v), 3) if math.isfinite(v) else None for v in shift],
    }
    if m["corners"] < MIN_CORNERS:
        ctx.log(f"cannot tell whether the camera moved: the background shows only {m['corners']} corners to follow")
    elif not math.isfinite(worst):
        ctx.log("cannot tell whether the camera moved: the background's corners could not be followed")
    elif moved:
        spans = ", ".join(f"{frames[r[0]]}-{frames[r[-1]]}" if len(r) > 1 else f"{frames[r[0]]}" for r in runs_of(over, 1))
        ctx.warn(f"the camera moved: the background shifts by up to {worst:.1f} px from frame {frames[0]}'s "
                 f"(frame {report['camera_shift_frame']}; more than {p.threshold_px:g} px on sampled frames {spans}). The capture assumes a "
                 f"camera that stays still for the whole take (one focal length, floor and pose), so its motion becomes "
                 f"the actor's: film from a tripod, or use the frames where it was still (--set decode.start=N / decode.stop=N)")
    else:
        ctx.log(f"camera still: the background moved at most {worst:.1f} px ({int(judged.sum()) - 1} of "
                f"{report['camera_motion_frames_sampled']} sampled frames judged, {m['corners']} corners)")
    return {"report": report}
