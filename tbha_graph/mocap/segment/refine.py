"""Hierarchical patch localisation inside search windows (seed 000, section 2).

For each window (a square of side ``size`` px cut from the full-resolution frame around a predicted
patch position), two cues are combined:

1. **Adaptive clustering** of the pixels by chroma: starting from the pixels the colour model accepts,
   the cluster's mean and covariance are estimated and the pixels within ``cluster_sigma`` Mahalanobis
   units collected, ``cluster_iterations`` times (the cluster adapts to the patch's actual colour under
   the current light). This sees the inside of the patch but leaves holes / notches at specular
   highlights. Region A: the cluster's region nearest the prediction (among the larger ones), traced by
   its outer contour and filled. (For the head's dark class the cluster is simply the pixels darker
   than ``dark_max_luma``.)
2. **Roberts cross edges** of the grey image (R + G + B) / 3, kept within ``edge_band`` px of region A:
   the patch's boundary including the blurred band between patch and suit, which clustering misses.
   Region B. (Grey, not the space's own luma: HSV's V hardly separates a saturated patch from white.)

The union A ∪ B is taken, its outer boundary traced (``cv2.findContours``), and the histograms of the
boundary points' x and y coordinates computed; the two farthest-apart histogram peaks in each give the
patch's bounding rectangle, whose centre is the joint's 2D position.

All windows are processed at once: the colour statistics on a ``(m, size, size)`` stack, the OpenCV
steps on one tall image of the windows stacked vertically; only the choice of each window's region
loops in Python. Coordinates are pixels from the frame's top-left.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..color.spaces import index_planes, wedge_distance_sq
from .labels import PixelClassifier


@dataclass(frozen=True)
class RefineSettings:
    """Tuning of :func:`refine_windows` (documented on the ``segment.hierarchical`` params)."""

    cluster_sigma: float = 3.0
    cluster_iterations: int = 2
    edge_fraction: float = 0.3
    edge_band: int = 2
    peak_fraction: float = 0.3
    min_area: float = 8.0
    centre: str = "rectangle"


@dataclass
class WindowResults:
    """Per window: ``ok`` (m,) bool (a region was found), ``centres`` (m, 2) px, ``areas`` (m,) px²,
    ``boxes`` (m, 4) x0, y0, x1, y1 px, ``diameters`` (m,) px, ``means`` (m, 2) adapted chroma mean,
    ``touches`` (m,) bool (the region reached the window border: the window may have cut it)."""

    ok: np.ndarray
    centres: np.ndarray
    areas: np.ndarray
    boxes: np.ndarray
    diameters: np.ndarray
    means: np.ndarray
    touches: np.ndarray


def window_origins(centres: np.ndarray, size: int, width: int, height: int) -> np.ndarray:
    """Top-left corners (m, 2) int of ``size``-px windows centred on ``centres`` (m, 2), kept inside the frame."""
    c = np.nan_to_num(np.asarray(centres, dtype=np.float64).reshape(-1, 2))
    o = np.rint(c - (size - 1) / 2.0).astype(np.int64)
    o[:, 0] = np.clip(o[:, 0], 0, max(width - size, 0))
    o[:, 1] = np.clip(o[:, 1], 0, max(height - size, 0))
    return o


def cut_windows(frame: np.ndarray, origins: np.ndarray, size: int) -> np.ndarray:
    """Stack of windows ``(m, size, size, 3)`` cut from ``frame`` at ``origins`` (m, 2) (x, y)."""
    return np.stack([frame[y : y + size, x : x + size] for x, y in origins]) if len(origins) else np.zeros((0, size, size, 3), np.uint8)


def farthest_peaks(hist: np.ndarray, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """The two farthest-apart peaks of each row of ``hist`` (m, n) (histograms with 1 px bins).

    A peak is a local maximum holding at least ``fraction`` of its row's highest bin; each is refined to
    sub-pixel by the count-weighted mean of its bin and its two neighbours. Returns the low and high
    peak positions (m,) in bin units; NaN for empty rows.
    """
    hist = np.asarray(hist, dtype=np.float64)
    h = np.zeros((hist.shape[0], hist.shape[1] + 2))
    h[:, 1:-1] = hist
    mid = h[:, 1:-1]
    top = mid.max(axis=1, keepdims=True)
    peak = (mid >= h[:, :-2]) & (mid >= h[:, 2:]) & (mid >= fraction * top) & (mid > 0)
    rows = np.arange(len(h))
    first = np.argmax(peak, axis=1) + 1  # index into the padded rows
    last = h.shape[1] - 2 - np.argmax(peak[:, ::-1], axis=1)

    idx = np.stack([first, last])  # (2, m)
    lo, c, hi = h[rows, idx - 1], h[rows, idx], h[rows, idx + 1]
    a, b = (idx - 1) + (hi - lo) / np.maximum(lo + c + hi, 1e-12)
    empty = top[:, 0] <= 0
    a[empty] = np.nan
    b[empty] = np.nan
    return a, b


def _chroma_clusters(idx, luma3, classes, clf: PixelClassifier, s: RefineSettings):
    """Adaptive clustering on a stack of windows: member mask (m, S, S) bool and the cluster means (m, 2).

    ``idx`` (m, S, S) uint16 chroma table indices and ``luma3`` (m, S, S) 3 x luma of the windows
    (:func:`~tbha_graph.mocap.color.spaces.index_planes`); ``classes`` (m,) the colour class of each.

    Start: the pixels the colour model accepts (chroma in the colour's wedge, not near the suit's
    white, luma at least ``min_luma``). Then, ``cluster_iterations`` times: mean and covariance of the
    cluster, and the new cluster = the pixels within ``cluster_sigma`` Mahalanobis units. The mean is
    kept inside the half-width wedge and the ellipse bounded, and only pixels within 1.5 times the
    wedge's width can ever join: the iterations run on those alone (their chroma read from the
    classifier's tables), with per-window sums by ``np.add.reduceat``.
    """
    model = clf.model
    m = len(classes)
    ref_all, pale_all, tol_all = model.segments()
    ref, pale, tols = ref_all[classes], pale_all[classes], tol_all[classes]
    g2 = s.cluster_sigma**2
    # variance of one axis of a 2D Gaussian truncated at cluster_sigma, relative to the untruncated one
    e = np.exp(-g2 / 2.0)
    kappa = 1.0 - (g2 / 2.0) * e / (1.0 - e)
    length = np.linalg.norm(pale - ref, axis=1)
    var_hi = ((tols + 0.5 * length) / s.cluster_sigma) ** 2  # (m,): along the wedge
    var_lo = (tols / s.cluster_sigma) ** 2 * 0.02
    table = idx.astype(np.int64) + (np.asarray(classes, np.int64) * 65536)[:, None, None]
    q = clf.wedge_q.reshape(-1).take(table)
    cand = (q < np.uint8(round(1.5**2 * clf.D2_SCALE))) & (luma3 >= 3.0 * model.min_luma)
    where = np.flatnonzero(cand)
    member = np.zeros(cand.size, bool)
    mu = (ref + pale) / 2.0
    if where.size == 0:
        return member.reshape(cand.shape), mu
    win = where // (cand.shape[1] * cand.shape[2])
    ti = idx.reshape(-1)[where]
    x1 = clf.c1.take(ti).astype(np.float64)
    x2 = clf.c2.take(ti).astype(np.float64)
    inl = q.reshape(-1)[where] <= np.uint8(clf.D2_SCALE)  # the colour model's own decision
    feats = np.stack([np.ones_like(x1), x1, x2, x1 * x1, x1 * x2, x2 * x2], axis=1)
    starts = np.searchsorted(win, np.arange(m))
    has = np.bincount(win, minlength=m) > 0
    cov = np.zeros((m, 2, 2))
    default = np.zeros((m, 2, 2))
    default[:, 0, 0] = default[:, 1, 1] = (tols / s.cluster_sigma) ** 2
    n_iter = max(1, s.cluster_iterations)
    for it in range(n_iter + 1):
        if it > 0:
            det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
            d1, d2 = x1 - mu[win, 0], x2 - mu[win, 1]
            m2 = (cov[win, 1, 1] * d1 * d1 - 2.0 * cov[win, 0, 1] * d1 * d2 + cov[win, 0, 0] * d2 * d2) / det[win]
            inl = m2 < g2
        if it == n_iter:
            break
        # per-window sums of 1, x1, x2, x1², x1 x2, x2² over the cluster (``win`` is sorted)
        sums = np.zeros((m, 6))
        sums[has] = np.add.reduceat(feats * inl[:, None], starts[has], axis=0)
        n = sums[:, 0]
        ok = n >= s.min_area
        n1 = np.maximum(n, 1.0)
        s1, s2 = sums[:, 1] / n1, sums[:, 2] / n1
        s11 = sums[:, 3] / n1 - s1 * s1
        s12 = sums[:, 4] / n1 - s1 * s2
        s22 = sums[:, 5] / n1 - s2 * s2
        new_mu = np.stack([s1, s2], axis=1)
        # keep the mean inside the half-width wedge: pull it towards the nearest point of the axis
        dd = pale - ref
        t = np.clip(np.sum((new_mu - ref) * dd, axis=1) / np.maximum(np.sum(dd * dd, axis=1), 1e-12), 0, 1)
        near = ref + t[:, None] * dd
        dw = np.sqrt(wedge_distance_sq(new_mu[:, 0], new_mu[:, 1], model.suit_ref, (ref[:, 0], ref[:, 1]), (pale[:, 0], pale[:, 1]), tols))
        pull = np.where(dw > 0.5, 0.5 / np.maximum(dw, 1e-12), 1.0)[:, None]
        new_mu = near + (new_mu - near) * pull
        new_cov = np.stack([np.stack([s11, s12], -1), np.stack([s12, s22], -1)], -2) / (kappa if it > 0 else 1.0)
        evals, evecs = np.linalg.eigh(new_cov)
        evals = np.clip(evals, var_lo[:, None], var_hi[:, None])
        new_cov = np.einsum("mij,mj,mkj->mik", evecs, evals, evecs)
        mu = np.where(ok[:, None], new_mu, mu)
        cov = np.where(ok[:, None, None], new_cov, cov if it > 0 else default)
    member[where[inl]] = True
    return member.reshape(cand.shape), mu


def _grey(stack: np.ndarray) -> np.ndarray:
    """Grey level (B + G + R) / 3 of a BGR uint8 stack (m, S, S, 3), float32 (m, S, S)."""
    return stack.sum(axis=-1, dtype=np.float32) * np.float32(1.0 / 3.0)


def _roberts(luma: np.ndarray) -> np.ndarray:
    """Roberts cross gradient magnitude ``|I(x,y) - I(x+1,y+1)| + |I(x+1,y) - I(x,y+1)|`` of a stack
    (m, S, S). The operator answers for the centre of each 2x2 cell; each pixel gets the strongest of
    the (up to) four cells it belongs to, so edges are not shifted by half a pixel to the top-left."""
    m, h, w = luma.shape
    cell = np.zeros((m, h + 1, w + 1), luma.dtype)
    cell[:, 1:-1, 1:-1] = np.abs(luma[:, :-1, :-1] - luma[:, 1:, 1:]) + np.abs(luma[:, :-1, 1:] - luma[:, 1:, :-1])
    return np.maximum(np.maximum(cell[:, :-1, :-1], cell[:, :-1, 1:]), np.maximum(cell[:, 1:, :-1], cell[:, 1:, 1:]))


def refine_windows(
    frame: np.ndarray,
    origins: np.ndarray,
    size: int,
    predicted: np.ndarray,
    classes: list[int],
    clf: PixelClassifier,
    settings: RefineSettings,
) -> WindowResults:
    """Locate one patch per window (see module docstring).

    ``frame`` BGR uint8 (h, w, 3); ``origins`` (m, 2) window top-left corners; ``predicted`` (m, 2) px
    expected patch centres (the region nearest to it is chosen); ``classes`` (m,) class index into
    the colour model's classes; ``clf`` the colour model's :class:`~.labels.PixelClassifier`.

    The windows are processed as one tall image (windows stacked vertically, separated by empty rows
    wider than the edge band) so each OpenCV operation runs once per call, not once per window.
    """
    m = len(origins)
    out = WindowResults(
        ok=np.zeros(m, bool), centres=np.full((m, 2), np.nan), areas=np.zeros(m), boxes=np.full((m, 4), np.nan),
        diameters=np.zeros(m), means=np.full((m, 2), np.nan), touches=np.zeros(m, bool),
    )
    if m == 0:
        return out
    model = clf.model
    S = int(size)
    stack = cut_windows(frame, origins, S)
    idx, luma3 = index_planes(model.space, stack.reshape(m * S, S, 3))
    idx, luma3 = idx.reshape(m, S, S), luma3.reshape(m, S, S)
    kinds = np.array([model.classes[c].kind == "chroma" for c in classes])
    H = S + settings.edge_band + 1  # rows per window in the tall image
    member = np.zeros((m, H, S), np.uint8)
    if kinds.any():
        ci = np.flatnonzero(kinds)
        mem, mu = _chroma_clusters(idx[ci], luma3[ci], np.asarray(classes)[ci], clf, settings)
        member[ci, :S] = mem
        out.means[ci] = mu
    if (~kinds).any():
        di = np.flatnonzero(~kinds)
        member[di, :S] = luma3[di] < 3.0 * model.dark_max_luma

    # region A: per window, the clustered region nearest the prediction (among the larger ones), traced
    # by its outer contour and filled (so highlight holes inside the patch do not matter)
    contours, _ = cv2.findContours(member.reshape(m * H, S), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    local_pred = np.asarray(predicted, dtype=np.float64).reshape(m, 2) - origins
    found: dict[int, list[tuple[float, float, np.ndarray]]] = {}
    for c in contours:
        x, y, w, h = cv2.boundingRect(c)
        if w * h < settings.min_area:
            continue
        area = cv2.contourArea(c) + 0.5 * cv2.arcLength(c, True) + 1.0  # pixels, by Pick's theorem
        if area < settings.min_area:
            continue
        wi = y // H
        found.setdefault(wi, []).append((area, x + w / 2.0 - local_pred[wi, 0], y - wi * H + h / 2.0 - local_pred[wi, 1], c))
    chosen: list[np.ndarray] = []
    for wi, cands in found.items():
        big = 0.25 * max(a for a, *_ in cands)
        area, _, _, c = min((t for t in cands if t[0] >= big), key=lambda t: t[1] * t[1] + t[2] * t[2])
        chosen.append(c)
        x, y, w, h = cv2.boundingRect(c)
        y -= wi * H
        out.touches[wi] = x == 0 or y == 0 or x + w >= S or y + h >= S
    if not chosen:
        return out
    region = np.zeros((m * H, S), np.uint8)
    cv2.drawContours(region, chosen, -1, 255, thickness=-1)
    chosen_windows = set(found)

    # region B: Roberts edges within edge_band px of A, thresholded relative to the strongest there
    k = 2 * settings.edge_band + 1
    band = cv2.dilate(region, np.ones((k, k), np.uint8)).reshape(m, H, S) > 0
    mag = np.zeros((m, H, S), np.float32)
    grey = luma3.astype(np.float32) * np.float32(1.0 / 3.0) if model.space == "rg" else _grey(stack)
    mag[:, :S] = _roberts(grey)
    peak = np.where(band, mag, 0).reshape(m, -1).max(axis=1)
    thr = np.where(peak > 0, settings.edge_fraction * peak, np.inf).astype(np.float32)
    union = (region.reshape(m, H, S) > 0) | ((mag > thr[:, None, None]) & band)

    # boundary of A ∪ B, histograms of its x and y, farthest-apart peaks -> rectangle -> centre
    u8 = union.view(np.uint8).reshape(m * H, S)
    contours, _ = cv2.findContours(u8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    best: dict[int, np.ndarray] = {}
    for c in contours:
        w = int(c[0, 0, 1]) // H
        if w in chosen_windows and (w not in best or len(c) > len(best[w])):
            best[w] = c
    if not best:
        return out
    wins = np.fromiter(best, dtype=np.int64, count=len(best))
    pts = np.concatenate([best[w].reshape(-1, 2) for w in wins])
    wid = np.repeat(wins, [len(best[w]) for w in wins])
    hx = np.bincount(wid * S + pts[:, 0], minlength=m * S).reshape(m, S)[wins]
    hy = np.bincount(wid * S + (pts[:, 1] - wid * H), minlength=m * S).reshape(m, S)[wins]
    lo, hi = farthest_peaks(np.concatenate([hx, hy]), settings.peak_fraction)
    x0, y0 = np.split(lo, 2)
    x1, y1 = np.split(hi, 2)
    ox, oy = origins[wins, 0], origins[wins, 1]
    out.ok[wins] = True
    out.centres[wins] = np.stack([(x0 + x1) / 2.0 + ox, (y0 + y1) / 2.0 + oy], axis=1)
    if settings.centre == "centroid":  # alternative: centroid of the filled outer boundary
        for w in wins:
            mo = cv2.moments(best[w])
            if mo["m00"] > 0:
                out.centres[w] = (mo["m10"] / mo["m00"] + origins[w, 0], mo["m01"] / mo["m00"] - w * H + origins[w, 1])
    out.boxes[wins] = np.stack([x0 + ox, y0 + oy, x1 + ox, y1 + oy], axis=1)
    out.areas[wins] = union.reshape(m, -1).sum(axis=1)[wins]
    out.diameters[wins] = np.maximum(x1 - x0, y1 - y0) + 1.0
    return out
