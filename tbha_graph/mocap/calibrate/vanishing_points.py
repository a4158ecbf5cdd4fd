"""``calibrate.vanishing_points``: the focal length from the room's straight lines (floor tiles, wall edges).

Lines that are parallel in the world meet in the image at a vanishing point. The rays to the vanishing
points ``v1``, ``v2`` (pixels) of two perpendicular directions are perpendicular, so with the principal
point ``c`` at the image centre and square pixels ``(v1 - c)·(v2 - c) = -f²``. A person filmed by one
camera leaves the focal length nearly undetermined (``bench/focal_profile.py``: a 20 % change costs the
whole-take solve 1-7 %); a tiled floor or a room's edges fix it (renders: within 1 % when the camera looks
at the room obliquely).

1. **Background**: the per-pixel median of ``samples`` frames spread over the take (the actor moves, the
   room stays).
2. **Segments**: OpenCV's fast line detector (``cv2.ximgproc``) on it; those longer than ``min_length``
   (fraction of the image width), each re-fitted to its edge's sub-pixel position (``subpixel``).
3. **Vanishing points**: RANSAC. Two segments' lines meet at a candidate; every segment whose direction
   points at it within ``angle_deg`` votes with its length. The best is refined (the homogeneous point
   nearest all its segments' lines, weighted by length), its segments removed, and the search repeated,
   ``max_points`` times at most.
4. **Focal length**: of the pairs of finite vanishing points whose ``f`` lies in 0.3-8 x the image width
   and whose families each carry ``min_share`` of all the segments' length, the one whose weaker family has
   the most. From that start, one least-squares fit of the focal length and the three perpendicular
   directions (camera frame) to every segment of both families (:func:`manhattan_fit`: each segment's angle
   to its vanishing point, weighted by its length; when the two families span a level floor, a prior that
   the camera is not rolled, ``roll_sd_deg``, which pins a far sideways vanishing point that few lines leave
   loose). Its standard deviation from a bootstrap over the two families' segments (``bootstrap``
   resamples); when they lie on the floor, the floor's up direction in the camera frame too (the camera's
   tilt and roll), for the solver's floor.

No such pair (a plain background; a room seen square-on, whose sideways lines stay parallel in the image)
gives ``focal_px`` None and a warning: the solver then estimates the focal length from the take alone. The
assumption is a room whose main lines are perpendicular (floor tiles, walls): lines at other angles that
happen to pass the tests give a wrong focal length, and the bootstrap cannot see that.

A video read with a lens file (``io.video``'s ``lens``: its distortion removed, its focal length known) gives the
file's focal length instead (sd :data:`LENS_FILE_SD_PCT`), and the floor's tilt from the lines when their own focal
length agrees with it; when the lines say something else with confidence (:data:`LENS_FILE_DISAGREE`), a warning
that the file may be another camera's or zoom's.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.atomic import atomic_write_bytes
from ...core.node import checkpoint, node
from ..bundles.lens import LensEstimate
from ..io.video import iter_frames_at
from ..ports import IMAGE, LENS, REPORT, VIDEO

#: BGR colours of the two families that gave the focal length, then of the others
FAMILY_COLOURS = ((40, 40, 230), (230, 120, 30), (150, 150, 150))


class VanishingParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    samples: int = Field(25, ge=3, le=200, description="frames spread over the take whose median is the room")
    min_length: float = Field(0.04, gt=0, le=0.5, description="shortest segment used, as a fraction of the image width")
    angle_deg: float = Field(1.0, gt=0, le=10, description="a segment votes for a vanishing point it points at within this angle", json_schema_extra={"unit": "deg"})
    max_points: int = Field(4, ge=2, le=8, description="vanishing points searched for")
    min_segments: int = Field(5, ge=2, description="fewest segments a vanishing point needs")
    min_share: float = Field(0.1, ge=0, le=0.5, description="each of the two families giving the focal length carries at least this "
                             "fraction of all the segments' length (a few stray edges never decide it)")
    hypotheses: int = Field(2000, ge=100, description="RANSAC candidates per vanishing point")
    bootstrap: int = Field(100, ge=10, description="bootstrap resamples for the focal length's standard deviation")
    max_sd_pct: float = Field(10.0, gt=0, description="a focal length more uncertain than this (1 sd, %) is not passed on", json_schema_extra={"unit": "%"})
    roll_sd_deg: float = Field(1.0, gt=0, description="prior on the camera's roll when the two families lie on a level "
                               "floor (a tripod keeps the horizon level)", json_schema_extra={"unit": "deg"})
    subpixel: bool = Field(True, description="re-fit each segment to its edge's sub-pixel position (the line detector's "
                           "whole-pixel fits tilt short segments towards the pixel grid and bias the focal length high)")
    seed: int = Field(0, ge=0, description="random seed of RANSAC and the bootstrap")


def median_background(clip, samples: int, progress=None) -> np.ndarray:
    """Per-pixel median ``(H, W, 3)`` uint8 of ``samples`` frames spread evenly over ``clip`` (:func:`iter_frames_at`);
    ``progress`` (optional) wraps the frames' iterable as ``ctx.progress`` does (shown, and an interrupted run
    stops at the next frame)."""
    picks = np.unique(np.linspace(clip.start, clip.stop - 1, min(samples, clip.n_frames)).round().astype(int))
    frames = iter_frames_at(clip, picks)
    if progress is not None:
        frames = progress(frames, total=len(picks), desc="room background")
    return np.median(np.stack([frame for _, frame in frames]), axis=0).astype(np.uint8)


def line_segments(image: np.ndarray, min_length_px: float, subpixel: bool = True) -> np.ndarray:
    """Straight segments ``(k, 4)`` ``(x1, y1, x2, y2)`` px of a BGR image, longer than ``min_length_px``;
    ``subpixel``: each re-fitted to its edge's sub-pixel position (:func:`refine_segments`)."""
    import cv2

    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found = cv2.ximgproc.createFastLineDetector().detect(grey)
    seg = np.zeros((0, 4)) if found is None else found.reshape(-1, 4).astype(np.float64)
    seg = seg[np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > min_length_px]
    return refine_segments(grey, seg) if subpixel and len(seg) else seg


def refine_segments(grey: np.ndarray, seg: np.ndarray, spacing_px: float = 2.0, reach_px: float = 3.0,
                    step_px: float = 0.5, min_samples: int = 6, chunk: int = 64) -> np.ndarray:
    """Segments ``(k, 4)`` px re-fitted to the sub-pixel edge of the grey image ``(H, W)`` across them.

    The line detector fits its lines to whole-pixel edge points, which tilts short, nearly horizontal or vertical
    segments towards the pixel grid: lines that should converge look more parallel, far vanishing points move
    farther out and the focal length comes out high (the project's rendered room without the actor, 28 views:
    +1.2 % on average, RMS 1.9 %, median |error| 1.5 %; refitted -0.4 %, RMS 1.1 %, median 0.6 %; short
    area-sampled edges 0.21 -> 0.10 degrees: ``tests/mocap/test_vanishing_points.py``). At points along the
    middle 80 % of each segment (its ends meet corners and other edges), at most ``spacing_px`` apart, the image
    gradient across it is read every ``step_px`` within ``reach_px`` (bilinear), its peak of the segment's
    polarity located to a fraction of a step (parabola through the peak and its neighbours), and a straight line
    fitted to those peaks by least squares; a segment with fewer than ``min_samples`` clear peaks is kept as found.
    ``chunk`` segments at a time, so memory stays bounded on large images."""
    import cv2

    g = grey.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    longest = float(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]).max())
    samples = max(24, int(np.ceil(longest / spacing_px)))  # one count for all: the longest every spacing_px
    t = 0.1 + 0.8 * (np.arange(samples) + 0.5) / samples  # along a segment (fraction of its length), ends left out
    off = np.arange(-reach_px, reach_px + 1e-9, step_px)  # across it, px
    return np.concatenate([_refit(gx, gy, seg[i:i + chunk], t, off, step_px, min_samples)
                           for i in range(0, len(seg), chunk)])


def _refit(gx: np.ndarray, gy: np.ndarray, seg: np.ndarray, t: np.ndarray, off: np.ndarray, step_px: float,
           min_samples: int) -> np.ndarray:
    """:func:`refine_segments` on segments ``(k, 4)``: the image's gradients ``gx``, ``gy`` ``(H, W)`` float32, the
    sample points along (``t``, fractions) and across (``off``, px) each segment."""
    import cv2

    a, b = seg[:, :2], seg[:, 2:]
    length = np.linalg.norm(b - a, axis=1)
    d = (b - a) / length[:, None]
    n = np.c_[-d[:, 1], d[:, 0]]
    samples = len(t)
    pts = (a[:, None, None] + (t[None, :, None, None] * length[:, None, None, None]) * d[:, None, None]
           + off[None, None, :, None] * n[:, None, None])  # (k, samples, offsets, 2)
    mx = pts[..., 0].reshape(len(seg), -1).astype(np.float32)
    my = pts[..., 1].reshape(len(seg), -1).astype(np.float32)
    shape = (len(seg), samples, len(off))
    across = (cv2.remap(gx, mx, my, cv2.INTER_LINEAR).reshape(shape) * n[:, None, None, 0]
              + cv2.remap(gy, mx, my, cv2.INTER_LINEAR).reshape(shape) * n[:, None, None, 1])
    across *= np.sign(across.sum(axis=(1, 2)))[:, None, None]  # the segment's polarity, positive
    k = np.clip(np.argmax(across, axis=2), 1, len(off) - 2)
    lo, mid, hi = (np.take_along_axis(across, (k + s)[..., None], 2)[..., 0] for s in (-1, 0, 1))
    curv = lo - 2.0 * mid + hi
    peak = (mid >= np.maximum(lo, hi)) & (curv < 0) & (mid > 0)  # a maximum (or a tie of two) inside the reach
    shift = off[k] + np.clip(0.5 * (lo - hi) / np.where(peak, curv, -1.0), -0.5, 0.5) * step_px
    w = peak.astype(np.float64)
    sw = w.sum(axis=1)
    tc = t - 0.5
    mt = (w * tc).sum(axis=1) / np.maximum(sw, 1.0)
    ms = (w * shift).sum(axis=1) / np.maximum(sw, 1.0)
    slope = ((w * (tc - mt[:, None]) * (shift - ms[:, None])).sum(axis=1)
             / np.maximum((w * (tc - mt[:, None]) ** 2).sum(axis=1), 1e-9))
    at_a, at_b = ms + slope * (-0.5 - mt), ms + slope * (0.5 - mt)  # the fitted line's shift at the two ends
    ok = sw >= min_samples
    out = seg.copy()
    out[ok, :2] = a[ok] + at_a[ok, None] * n[ok]
    out[ok, 2:] = b[ok] + at_b[ok, None] * n[ok]
    return out


def segment_lines(seg: np.ndarray) -> np.ndarray:
    """Homogeneous lines ``(k, 3)`` through the segments, scaled so ``(a, b)`` is a unit normal."""
    a = np.c_[seg[:, :2], np.ones(len(seg))]
    b = np.c_[seg[:, 2:], np.ones(len(seg))]
    ln = np.cross(a, b)
    return ln / np.linalg.norm(ln[:, :2], axis=1, keepdims=True)


def signed_sine(seg: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(m, k)``: signed sine of the angle between each of ``k`` segments and the direction from its midpoint to
    each of ``m`` homogeneous points ``v`` ``(m, 3)`` (a point at infinity: its direction); smooth in ``v``."""
    mid = 0.5 * (seg[:, :2] + seg[:, 2:])
    d = seg[:, 2:] - seg[:, :2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = v[:, None, :2] - mid[None] * v[:, None, 2:3]  # (m, k, 2), up to sign and scale
    cross = t[..., 0] * d[None, :, 1] - t[..., 1] * d[None, :, 0]
    return cross / np.maximum(np.linalg.norm(t, axis=-1), 1e-12)


def pointing_sine(seg: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(m, k)``: how far (sine of the angle) each segment is from pointing at each point (:func:`signed_sine`)."""
    return np.abs(signed_sine(seg, v))


def refine_point(lines: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The unit homogeneous point ``(3,)`` nearest the ``lines`` ``(k, 3)`` in weighted least squares."""
    return np.linalg.svd(lines * weight[:, None], full_matrices=False)[2][-1]


def find_vanishing_points(seg: np.ndarray, p: VanishingParams, rng: np.random.Generator) -> list[np.ndarray]:
    """Index arrays of the segments voting for each vanishing point found (strongest first)."""
    lines = segment_lines(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    thr = np.sin(np.radians(p.angle_deg))
    left = np.arange(len(seg))
    families: list[np.ndarray] = []
    while len(families) < p.max_points and len(left) >= p.min_segments:
        pairs = rng.integers(0, len(left), size=(p.hypotheses, 2))
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        cand = np.cross(lines[left[pairs[:, 0]]], lines[left[pairs[:, 1]]])
        norm = np.linalg.norm(cand, axis=1)
        cand = cand[norm > 1e-12] / norm[norm > 1e-12, None]
        if not len(cand):
            break
        votes = (pointing_sine(seg[left], cand) < thr) @ length[left]
        best = cand[int(np.argmax(votes))]
        inl = pointing_sine(seg[left], best[None])[0] < thr
        if inl.sum() < 2:
            break
        best = refine_point(lines[left[inl]], length[left[inl]])
        inl = pointing_sine(seg[left], best[None])[0] < thr
        if inl.sum() < p.min_segments:
            break
        families.append(left[inl])
        left = left[~inl]
    return families


def manhattan_fit(seg: np.ndarray, fam_a: np.ndarray, fam_b: np.ndarray, va: np.ndarray, vb: np.ndarray, f0: float,
                  centre: np.ndarray, p: "VanishingParams") -> tuple[float, np.ndarray, bool]:
    """The focal length and the three perpendicular directions ``(3, 3)`` (columns: family a, family b, their
    normal; camera frame) fitted to every segment of both families at once (each one's angle to its vanishing
    point, weighted by length), with, when the two families span a level plane (their normal within 25° of the
    image's vertical: a floor), a prior that the camera is not rolled (``roll_sd_deg``): a tripod keeps the
    horizon level, which pins a far sideways vanishing point a few lines leave loose. Returns ``(f px,
    directions, levelled)``."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    def ray(v, f):  # K^-1 v, unit
        r = np.array([v[0] - centre[0] * v[2], v[1] - centre[1] * v[2], f * v[2]])
        return r / np.linalg.norm(r)

    da = ray(va, f0)
    db = ray(vb, f0)
    db = db - (db @ da) * da
    db /= np.linalg.norm(db)
    D0 = np.stack([da, db, np.cross(da, db)], axis=1)
    levelled = abs(D0[1, 2]) > np.cos(np.radians(25.0))
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    wa = length[fam_a] / length.mean()  # a segment's direction is known to about (pixel noise / length)
    wb = length[fam_b] / length.mean()
    s_ang, s_roll = np.sin(np.radians(p.angle_deg / 2.0)), np.sin(np.radians(p.roll_sd_deg))

    def directions(x):
        return Rotation.from_rotvec(x[1:]).as_matrix() @ D0

    def vp(d, f):
        return np.array([f * d[0] + centre[0] * d[2], f * d[1] + centre[1] * d[2], d[2]])

    def residuals(x):
        f, D = np.exp(x[0]), directions(x)
        out = [signed_sine(seg[fam_a], vp(D[:, 0], f)[None])[0] * wa / s_ang,
               signed_sine(seg[fam_b], vp(D[:, 1], f)[None])[0] * wb / s_ang]
        if levelled:  # the plane's normal (up or down) has no sideways component in the camera frame
            out.append(np.array([D[0, 2] / s_roll]))
        return np.concatenate(out)

    sol = least_squares(residuals, np.r_[np.log(f0), 0.0, 0.0, 0.0], method="lm")
    return float(np.exp(sol.x[0])), directions(sol.x), bool(levelled)


def focal_from_pair(va: np.ndarray, vb: np.ndarray, centre: np.ndarray) -> float | None:
    """Focal length (px) from two homogeneous vanishing points of perpendicular directions; None if not finite
    or the geometry gives none."""
    if abs(va[2]) < 1e-12 or abs(vb[2]) < 1e-12:
        return None
    f2 = -float(np.dot(va[:2] / va[2] - centre, vb[:2] / vb[2] - centre))
    return float(np.sqrt(f2)) if f2 > 0 else None


def estimate_focal(image: np.ndarray, p: VanishingParams) -> dict:
    """``{"focal_px", "focal_sd_pct", "segments", "families": [[x, y] or None, count, length px], "pair",
    "reason"}`` for one background image; ``focal_px`` None with ``reason`` when no perpendicular pair is found.
    Keys starting with ``_`` hold the segments and their families for :func:`draw_lines`."""
    h, w = image.shape[:2]
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    rng = np.random.default_rng(p.seed)
    seg = line_segments(image, p.min_length * w, p.subpixel)
    out: dict = {"segments": int(len(seg)), "families": [], "focal_px": None, "focal_sd_pct": None, "_seg": seg}
    if len(seg) < 2 * p.min_segments:
        out["reason"] = f"{len(seg)} straight edges in the background (a plain one?): too few for vanishing points"
        return out
    lines = segment_lines(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    fams = find_vanishing_points(seg, p, rng)
    out["_families"] = fams
    points = [refine_point(lines[i], length[i]) for i in fams]
    for v, i in zip(points, fams):
        at = [round(float(v[0] / v[2]), 1), round(float(v[1] / v[2]), 1)] if abs(v[2]) > 1e-12 else None
        out["families"].append([at, int(len(i)), round(float(length[i].sum()), 1)])
    best = None
    for a in range(len(fams)):
        for b in range(a + 1, len(fams)):
            f = focal_from_pair(points[a], points[b], centre)
            support = min(length[fams[a]].sum(), length[fams[b]].sum())  # the weaker family's length
            if f is None or not 0.3 * w <= f <= 8.0 * w or support < p.min_share * length.sum():
                continue
            if best is None or support > best[0]:
                best = (support, a, b, f)
    if best is None:
        out["reason"] = (f"{len(fams)} vanishing points, no two of them perpendicular with a plausible focal length "
                         "(a room seen square-on keeps its sideways lines parallel)")
        return out
    _, a, b, f_pair = best
    f, D, levelled = manhattan_fit(seg, fams[a], fams[b], points[a], points[b], f_pair, centre, p)
    up = -np.sign(D[1, 2]) * D[:, 2]  # the floor's normal, pointing up (camera y is down)
    boot, tilt = [], []
    for _ in range(p.bootstrap):
        checkpoint()  # an interrupted run (Ctrl-C with --jobs > 1) stops here
        ia = rng.choice(fams[a], len(fams[a]))
        ib = rng.choice(fams[b], len(fams[b]))
        fb, Db, _ = manhattan_fit(seg, ia, ib, points[a], points[b], f, centre, p)
        boot.append(np.log(fb) if 0.3 * w <= fb <= 8.0 * w else np.nan)
        tilt.append(np.degrees(np.arccos(np.clip(abs(Db[:, 2] @ up), -1.0, 1.0))))
    boot = np.asarray(boot)
    sd = float(np.nanstd(boot)) * 100.0 if np.isfinite(boot).mean() > 0.9 else float("inf")
    out.update(focal_px=round(f, 2), focal_sd_pct=round(sd, 3) if np.isfinite(sd) else None, pair=[a, b],
               focal_pair_px=round(f_pair, 2), level_floor=levelled)
    if levelled:  # the two families span the floor: its normal too (the camera's tilt and roll)
        out.update(up_cam=[round(float(v), 6) for v in up],
                   up_sd_deg=round(max(float(np.sqrt(np.mean(np.square(tilt)))), 0.05), 3))
    if not np.isfinite(sd):
        out["reason"] = "the bootstrap often finds no focal length: the two directions are nearly degenerate"
    return out


def draw_lines(background: np.ndarray, found: dict, caption: str) -> np.ndarray:
    """The background (BGR) with the segments coloured by family (the two that gave the focal length red and
    blue, the others grey), each pair's segments extended towards its vanishing point, and ``caption``."""
    import cv2

    img = (0.6 * background + 0.4 * 255).astype(np.uint8)  # faded, so the lines stand out
    seg, fams, pair = found.get("_seg", np.zeros((0, 4))), found.get("_families", []), found.get("pair") or []
    for s in seg:
        cv2.line(img, (int(s[0]), int(s[1])), (int(s[2]), int(s[3])), (200, 200, 200), 1, cv2.LINE_AA)
    for k, idx in enumerate(fams):
        colour = FAMILY_COLOURS[pair.index(k)] if k in pair else FAMILY_COLOURS[2]
        for s in seg[idx]:
            a, b = s[:2], s[2:]
            if k in pair:  # extended both ways, thin: the lines of a family meet at its vanishing point
                d = (b - a) / max(np.linalg.norm(b - a), 1e-9) * 4 * img.shape[1]
                cv2.line(img, tuple(int(v) for v in a - d), tuple(int(v) for v in b + d), colour, 1, cv2.LINE_AA)
            cv2.line(img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), colour, 3, cv2.LINE_AA)
    h = img.shape[0]
    cv2.rectangle(img, (0, h - 26), (img.shape[1], h), (255, 255, 255), cv2.FILLED)
    cv2.putText(img, caption[:110], (6, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
    return img


#: The focal length's standard deviation, per cent, given to a lens file's (``io.video``'s ``lens``): a checkerboard
#: calibration of 10-20 views is good to a few tenths of a per cent
LENS_FILE_SD_PCT = 0.5
#: With a lens file, the room's floor tilt is used when the room's own focal length agrees with the file's within this
#: fraction (the tilt is found with it)
LENS_FILE_AGREE = 0.03
#: the room's lines (known to ``max_sd_pct`` or better) and a lens file further apart than this, and 3 of the
#: lines' sd: a warning (a lens file of another zoom, its focal length 20 % short: the lines 40 %, 12 sd, apart)
LENS_FILE_DISAGREE = 0.15


@node("calibrate.vanishing_points", version=4, inputs={"video": VIDEO},
      outputs={"lens": LENS, "report": REPORT, "picture": IMAGE}, params=VanishingParams)
def vanishing_points(ctx, video) -> dict:
    """The focal length from the room's straight lines (module docstring): ``lens`` for ``reconstruct.solve_take``
    (none, with a warning, when the background shows no two perpendicular families of lines)."""
    import cv2

    p: VanishingParams = ctx.params
    background = median_background(video, p.samples, ctx.progress)
    found = estimate_focal(background, p)
    f, sd = found["focal_px"], found["focal_sd_pct"]
    calibrated = video.lens
    if calibrated is not None:  # io.video removed a lens file's distortion: its focal length is known
        agree = f is not None and found.get("up_cam") and abs(f / calibrated.focal_px - 1.0) < LENS_FILE_AGREE
        lens = LensEstimate(focal_px=round(calibrated.focal_px, 2), focal_sd_pct=LENS_FILE_SD_PCT, width=video.width,
                            height=video.height, source=f"lens file {Path(calibrated.source).name}: "
                            f"{calibrated.focal_px:.0f} px" + (", the floor's tilt from the room's lines" if agree else ""),
                            up_cam=found.get("up_cam") if agree else None, up_sd_deg=found.get("up_sd_deg") if agree else None)
        ctx.log(lens.source + (f" (the room's lines gave {f:.0f} px)" if f is not None else ""))
        if f is not None and sd is not None and sd <= p.max_sd_pct and \
                abs(f / calibrated.focal_px - 1.0) > max(LENS_FILE_DISAGREE, 3 * sd / 100):
            ctx.warn(f"the room's lines give a focal length of {f:.0f} px ± {sd:.1f} %, the lens file "
                     f"{Path(calibrated.source).name} {calibrated.focal_px:.0f} px (used): a lens file of another camera "
                     "or zoom? Calibrate the lens with the camera, resolution and zoom of this take")
    elif f is not None and sd is not None and sd <= p.max_sd_pct:
        lens = LensEstimate(focal_px=f, focal_sd_pct=max(sd, 1e-3), width=video.width, height=video.height,
                            source=f"vanishing points of the room's lines: {f:.0f} px ± {sd:.1f} %"
                                   + (", and the floor's tilt" if found.get("up_cam") else ""),
                            up_cam=found.get("up_cam"), up_sd_deg=found.get("up_sd_deg"))
        ctx.log(lens.source)
    else:
        why = found.get("reason") or f"too uncertain: {f:.0f} px ± {sd:.0f} % (1 sd)"
        lens = LensEstimate(width=video.width, height=video.height, source=f"no focal length from the room: {why}")
        ctx.warn(f"no focal length from the room's lines ({why}); it is estimated from the take alone, which "
                 "leaves it 10-50 % off (25 % on average over 16 renders, up to 100 %) — give focal_px if you know it, "
                 "or, for a wide-angle or action camera whose lens bends straight lines, the lens.json of "
                 "pipelines/checkerboard.yaml as --var lens")
    _, png = cv2.imencode(".png", draw_lines(background, found, lens.source))
    picture = atomic_write_bytes(ctx.output_path("room_lines.png"), png.tobytes())
    report = {k: v for k, v in found.items() if not k.startswith("_")}
    return {"lens": lens, "report": {**report, "source": lens.source}, "picture": picture}
