"""``segment.silhouette``: the actor's outline in every frame, whatever way they face.

The suit's patches are on the body's front, so with the actor's back to the camera the tracker sees the
head alone; the body's outline against the background is seen all the same. This node gives the whole-take
solver (:mod:`..reconstruct.solve_take`) that outline as a **distance-outside field** per frame: for every
pixel, how far (pixels) it lies outside the actor's silhouette (0 inside it).

Method (the camera is still):

1. **Background.** Frames sampled evenly over the take (``background_samples``), downscaled by ``scale``;
   per pixel the median of the samples where the actor is not near that pixel — outside the box around that
   frame's *tracked* points (at least the body's height tall, grown by ``track_margin`` of it; a lost point the
   tracker holds may be stale). Where the actor is near in nearly every sample (fewer than
   ``min_background_samples`` others; a turn or a hop on the spot) the background is painted in from the
   known background around it (:func:`cv2.inpaint`, Telea).
2. **Foreground.** Each frame streamed again (:func:`..io.video.iter_frames`; never the whole take held at
   full resolution): a pixel is foreground where some colour channel differs from the background by more
   than ``threshold`` (8-bit levels), unless it only got darker by a similar factor in every channel (a
   shadow on the floor); an opening removes specks, a closing fills seams; regions smaller than
   ``min_region`` of the largest one are dropped (noise, not the actor); holes inside the outline are filled.
3. **Field.** :func:`cv2.distanceTransform` of the background (L2, 5x5 mask), at the reduced resolution,
   stored as ``uint8`` in reduced pixels (saturating at 255); 0 everywhere on a frame without foreground
   (the actor out of view: no constraint).

Output ``silhouette``: ``distance`` ``(n_frames, H', W')`` uint8 (reduced pixels outside the silhouette;
full-resolution pixels = value / scale), ``scale`` (reduced / full size), ``area_px`` ``(n_frames,)`` the
silhouette's area in full-resolution pixels², ``bottom_px`` ``(n_frames,)`` the image row (full-resolution px, y down) of
its lowest pixel (the sole of the lower foot; NaN on an empty frame), ``background_known_pct``, ``unknown_box_pct``
``(n_frames,)`` the % of each frame's actor box where the background is unknown.

Where the actor stays on one spot, what is behind them is never seen (painted in). That is a warning only where
it matters (:func:`unknown_background_warning`): on a run of frames whose torso patches are unseen (the actor's
back to the camera), where the outline is what places the body, with the actor standing on the unknown part;
a background known on less than 90 % of the image is otherwise a log line (the sample: its torso is seen on
every frame).
"""
from __future__ import annotations

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..bundles.tracks import body_boxes, read_tracks
from ..io.video import iter_frames
from ..ports import SILHOUETTE, TRACKS2D, VIDEO, VideoClip
from ..runs import runs_of, runs_text
from ..skeleton import torso_unseen

#: A frame's actor box (:func:`body_boxes`) more than this % of which lies where the background is unknown
#: counts as the actor standing on the unknown background
UNKNOWN_BOX_PCT = 20.0
#: Fewest consecutive such frames (with no torso patch seen) that make the unknown background a warning: over a
#: few frames the motion's smoothness carries the body across (a third of a second at 30 fps)
UNKNOWN_RUN_MIN_FRAMES = 10


class SilhouetteParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    scale: float = Field(0.5, gt=0, le=1, description="the field's resolution as a fraction of the frame's")
    background_samples: int = Field(64, ge=5, le=400, description="frames sampled evenly over the take for the background")
    min_background_samples: int = Field(3, ge=1, description="fewest actor-free samples that give a pixel its background")
    track_margin: float = Field(0.3, ge=0, le=2, description="where the actor may be: the box around a frame's tracked points, at least the body's height tall, grown by this fraction of the body's height")
    threshold: float = Field(28.0, gt=0, le=255, description="largest channel difference from the background that is still background", json_schema_extra={"unit": "8-bit level"})
    shadow_ratio: tuple[float, float] = Field((0.45, 0.97), description="a pixel darker than the background by a factor in this range in every channel, within shadow_spread of each other, is a shadow (background)")
    shadow_spread: float = Field(0.08, ge=0, le=1, description="largest spread of the three channels' darkening factors in a shadow")
    open_px: int = Field(3, ge=1, le=15, description="opening kernel (reduced pixels): specks removed")
    close_px: int = Field(5, ge=1, le=31, description="closing kernel (reduced pixels): seams filled")
    min_region: float = Field(0.05, ge=0, le=1, description="regions smaller than this fraction of the largest are dropped")


def _small(frame: np.ndarray, scale: float) -> np.ndarray:
    if scale >= 1.0:
        return frame
    h, w = frame.shape[:2]
    return cv2.resize(frame, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)


def box_masks(boxes: np.ndarray, shape: tuple[int, int], scale: float) -> np.ndarray:
    """``(k, H', W')`` bool: the reduced pixels inside each box ``(k, 4)`` full-resolution px (all for a NaN box)."""
    h, w = shape
    xs = (np.arange(w) + 0.5) / scale - 0.5
    ys = (np.arange(h) + 0.5) / scale - 0.5
    known = np.isfinite(boxes).all(axis=1)
    b = np.where(known[:, None], boxes, 0.0)
    inx = (xs[None, :] >= b[:, 0:1]) & (xs[None, :] <= b[:, 2:3])
    iny = (ys[None, :] >= b[:, 1:2]) & (ys[None, :] <= b[:, 3:4])
    return (iny[:, :, None] & inx[:, None, :]) | ~known[:, None, None]


def unknown_box_pct(known: np.ndarray, boxes: np.ndarray, scale: float, chunk: int = 64) -> np.ndarray:
    """``(n,)``: % of each frame's box ``(n, 4)`` (full-resolution px; a NaN box is the whole image) lying where the
    background is unknown (``known`` ``(H', W')`` False); in chunks of ``chunk`` frames (memory flat in the take's length)."""
    unknown = ~np.asarray(known, dtype=bool)
    out = np.empty(len(boxes))
    for a in range(0, len(boxes), chunk):
        m = box_masks(boxes[a:a + chunk], unknown.shape, scale)
        out[a:a + chunk] = 100.0 * (m & unknown).sum(axis=(1, 2)) / np.maximum(m.sum(axis=(1, 2)), 1)
    return out


def background_model(samples: np.ndarray, actor: np.ndarray, min_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel median background ``(H', W', 3)`` float32 of ``samples`` ``(k, H', W', 3)`` uint8 (reduced frames)
    over the samples where ``actor`` ``(k, H', W')`` says the actor is not, and the mask ``(H', W')`` of pixels
    with at least ``min_samples`` such samples."""
    k, h, w = samples.shape[:3]
    free = ~actor
    count = free.sum(axis=0)  # free samples per pixel
    bg = np.empty((h, w, 3), dtype=np.float32)
    rows = max(1, (8 << 20) // max(k * w * 3 * 4, 1))  # strips of about 8 MB of float32 samples
    for r in range(0, h, rows):
        s = samples[:, r:r + rows].astype(np.float32)
        f = free[:, r:r + rows]
        s[~f] = np.inf  # the actor's samples sort after the free ones
        s.sort(axis=0)
        c = count[r:r + rows, :, None]
        lo, hi = np.maximum((c - 1) // 2, 0), c // 2  # the middle one (c odd) or two (c even) of the sorted free ones
        # np.nanmedian's values (8-bit samples: their medians are whole or half numbers, exact in float32), 3.5x
        # faster; a pixel with no free sample gets 0, not kept: with fewer than min_samples free samples it is not
        # `known` and is painted in below
        med = 0.5 * (np.take_along_axis(s, lo[None], 0)[0] + np.take_along_axis(s, hi[None], 0)[0])
        bg[r:r + rows] = np.where(c > 0, med, 0.0)
    known = count >= min_samples
    if not known.all():  # the actor is always near: the background there painted in from around it
        bg = cv2.inpaint(np.clip(np.rint(bg), 0, 255).astype(np.uint8), (~known).astype(np.uint8), 5,
                         cv2.INPAINT_TELEA).astype(np.float32)
    return bg, known


def _channel_max(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=2)`` of an ``(H, W, 3)`` float32 array, the same values, by OpenCV on the split channels
    (numpy's reduction over a last axis of 3 is about 15x slower)."""
    c = cv2.split(a)
    return cv2.max(cv2.max(c[0], c[1]), c[2])


def _channel_min(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=2)`` of an ``(H, W, 3)`` float32 array, as :func:`_channel_max`."""
    c = cv2.split(a)
    return cv2.min(cv2.min(c[0], c[1]), c[2])


def changed(frame: np.ndarray, bg: np.ndarray, p: SilhouetteParams) -> np.ndarray:
    """``(H', W')`` uint8, 255 where the reduced BGR frame ``(H', W', 3)`` differs from the background ``bg`` by more
    than ``threshold`` in some channel and not as a shadow does (every channel dimmed or lit in the same ratio)."""
    f = frame.astype(np.float32)
    diff = _channel_max(cv2.absdiff(f, bg))  # OpenCV's elementwise float32 arithmetic: numpy's values, 10-25x faster
    one = (1.0, 1.0, 1.0, 0.0)  # a scalar per channel (OpenCV 4 adds a bare 1.0 to the first channel only)
    ratio = cv2.divide(cv2.add(f, one), cv2.add(bg, one))
    rmax, rmin = _channel_max(ratio), _channel_min(ratio)
    shadow = (rmax <= p.shadow_ratio[1]) & (rmin >= p.shadow_ratio[0]) & (rmax - rmin <= p.shadow_spread)
    return ((diff > p.threshold) & ~shadow).astype(np.uint8) * 255


def foreground(frame: np.ndarray, bg: np.ndarray, p: SilhouetteParams) -> np.ndarray:
    """The actor's mask ``(H', W')`` uint8 (255 = actor) in one reduced BGR frame ``(H', W', 3)``: :func:`changed`,
    opened and closed, its small regions dropped, holes filled."""
    fg = changed(frame, bg, p)
    fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (p.open_px, p.open_px)))
    fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (p.close_px, p.close_px)))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n > 2:
        area = stats[1:, cv2.CC_STAT_AREA]
        keep = np.r_[False, area >= p.min_region * area.max()]
        fg = np.where(keep[lab], 255, 0).astype(np.uint8)
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return cv2.drawContours(fg, contours, -1, 255, thickness=cv2.FILLED)  # holes filled (where the background is the actor's)


def distance_outside(fg: np.ndarray) -> np.ndarray:
    """Distance ``(H', W')`` uint8 (pixels of ``fg``'s resolution, saturating at 255) from each pixel to the
    nearest foreground pixel of ``fg`` (0 on the silhouette). An empty ``fg`` (the actor out of view, or not found)
    gives all 0: no constraint, rather than every point outside (measured on a take whose actor walks out of the
    image: the solver pulled the body into view, 213 -> 290 mm)."""
    if not fg.any():
        return np.zeros(fg.shape, dtype=np.uint8)
    d = cv2.distanceTransform(np.where(fg > 0, 0, 255).astype(np.uint8), cv2.DIST_L2, 5)
    return np.minimum(np.rint(d), 255).astype(np.uint8)


def silhouette_clip(clip: VideoClip, points: np.ndarray, tracked: np.ndarray, p: SilhouetteParams,
                    progress=None) -> dict[str, np.ndarray]:
    """The silhouette bundle of ``clip`` (see the module docstring); ``points`` ``(n, 16, 2)`` the 2D tracks,
    full-resolution pixels, ``tracked`` ``(n, 16)`` bool; ``progress`` (optional, as ``ctx.progress``: wraps an
    iterable) shows the two passes over the video, and an interrupted run stops at its next frame."""
    steps = (lambda it, desc: it) if progress is None else (lambda it, desc: progress(it, total=clip.n_frames, desc=desc))
    n = clip.n_frames
    if points.shape[0] != n:
        raise NodeError(f"the tracks have {points.shape[0]} frames, the video {n}",
                        hint="connect the tracks made from this video")
    pick = np.unique(np.linspace(0, n - 1, min(p.background_samples, n)).round().astype(int))
    picked = set(int(k) for k in pick)
    samples = []
    for i, frame in steps(iter_frames(clip), "silhouette: background"):
        if i - clip.start in picked:
            samples.append(_small(frame, p.scale))
    samples = np.stack(samples)
    boxes = body_boxes(points, tracked, p.track_margin)
    bg, known = background_model(samples, box_masks(boxes[pick], samples.shape[1:3], p.scale), p.min_background_samples)
    out, area, bottom = None, np.zeros(n), np.full(n, np.nan)
    for i, frame in steps(iter_frames(clip), "silhouette: outline"):
        fg = foreground(_small(frame, p.scale), bg, p)
        if out is None:
            out = np.empty((n,) + fg.shape, dtype=np.uint8)
        out[i - clip.start] = distance_outside(fg)
        area[i - clip.start] = np.count_nonzero(fg) / p.scale ** 2
        rows = np.flatnonzero(fg.any(axis=1))
        bottom[i - clip.start] = (rows[-1] + 1) / p.scale - 0.5 if rows.size else np.nan
    return {"distance": out, "scale": np.asarray(p.scale, dtype=np.float64), "area_px": area, "bottom_px": bottom,
            "background_known_pct": np.asarray(100.0 * known.mean()), "unknown_box_pct": unknown_box_pct(known, boxes, p.scale)}


def unknown_background_warning(known_pct: float, unknown_box: np.ndarray, tracked: np.ndarray,
                               first_frame: int) -> tuple[str, bool] | None:
    """What to say of the background the take never shows (``known_pct`` % of the image known), and whether it is
    a warning (True) or a log line, or None (nothing to say). It matters where the outline is what places the body:
    on the frames whose torso patches are unseen (:func:`..skeleton.torso_unseen` of ``tracked`` ``(n, 16)``: the
    actor's back to the camera), and only where the actor then stands on the unknown background (``unknown_box``
    ``(n,)``: % of the frame's actor box there, above :data:`UNKNOWN_BOX_PCT`) for :data:`UNKNOWN_RUN_MIN_FRAMES`
    frames or more in a row: a warning naming them, however much of the whole image is known (an actor turning on
    one spot leaves little of it unknown). Otherwise a background known on less than 90 % of the image is a log line
    saying why it does not matter. Frame numbers from ``first_frame``."""
    unseen = torso_unseen(tracked)
    runs = runs_of(unseen & (np.asarray(unknown_box) > UNKNOWN_BOX_PCT), min_len=UNKNOWN_RUN_MIN_FRAMES)
    if runs:
        return (f"on frames {runs_text(runs, first_frame)} no torso patch is seen, so the actor's outline places the body, "
                f"and the actor stands where the background is never seen ({known_pct:.0f} % of the image is known): the "
                "outline there is found against a painted-in background, which a textured wall makes unreliable "
                "(check the overlay)"), True
    if known_pct >= 90.0:
        return None
    where = (f"where no torso patch is seen ({int(unseen.sum())} frames) the actor stands on it for less than "
             f"{UNKNOWN_RUN_MIN_FRAMES} frames in a row" if unseen.any() else "the torso's patches are seen on every frame, so the patches place the body")
    return (f"the background is known on {known_pct:.0f} % of the image only (the actor stays on the same spot); "
            f"that does not matter here: {where}"), False


@node(
    "segment.silhouette",
    version=2,
    inputs={"video": VIDEO, "tracks": TRACKS2D},
    outputs={"silhouette": SILHOUETTE},
    params=SilhouetteParams,
)
def silhouette(ctx, video, tracks) -> dict:
    """The actor's silhouette per frame as a distance-outside field (background: per-pixel median of the
    frames where the tracks put the actor elsewhere)."""
    p: SilhouetteParams = ctx.params
    clip = VideoClip.model_validate(video) if isinstance(video, dict) else video
    tr = read_tracks(tracks)
    pts = np.asarray(tr.points, dtype=np.float64)
    out = silhouette_clip(clip, pts, np.asarray(tr.tracked, dtype=bool), p, progress=ctx.progress)
    known = float(out["background_known_pct"])
    ctx.log(f"background known on {known:.1f} % of the image; silhouette area median {np.median(out['area_px']):.0f} px²")
    said = unknown_background_warning(known, out["unknown_box_pct"], np.asarray(tr.tracked, dtype=bool), clip.start)
    if said is not None:
        (ctx.warn if said[1] else ctx.log)(said[0])
    return {"silhouette": out}
