"""White balance from the suit: undo a coloured light or a camera's white balance before the patches are classified.

The colour model holds the suit's colours as the suit file gives them (:mod:`.model`), i.e. as a camera
balanced on the suit's white sees them. Under a warm (tungsten) or cool (shade) light, or with the camera's
white balance off, every chromaticity moves: the white suit is no longer near the model's white and the
patches leave their wedges (a warm light put blue and cyan outside theirs and the take failed at its
T-pose). Such a light is, to first order, one gain per channel (von Kries), so it is undone by the gains
that map the suit's observed white back to the suit file's white.

Where is the suit's white? It is the brightest near-uniform surface of the body, but a lit wall can be
brighter than a dimly lit suit. So candidates are taken from the image, and the colour model judges them:

1. **Candidates**: in each sample frame (half resolution), among the pixels with no channel clipped (>= 250),
   those at least as bright as the 99.5th / 98th / 95th percentile; the mode of their chromaticity (a
   smoothed 2D histogram) and the mean BGR of the pixels near it is one candidate white.
2. **Judge**: each candidate's gains (and no correction at all) are applied to the sample frames and the
   frames classified (:class:`~tbha_graph.mocap.segment.labels.PixelClassifier`); a colour is *complete*
   in a frame when it has as many regions as joints wear it, none larger than ``FLOOD_FRACTION`` of the
   frame (a flood: the suit taken for a colour), and the colours' *fit* is how far their pixels lie from
   the colours' axes (a tinted patch sits at its wedge's border or in a neighbour's). Most complete
   (frame, colour) pairs win, then the best fit; no correction is kept unless a candidate completes more
   colours or fits clearly better (``FIT_GAIN``), so a video the model already reads is left as it is.
   (Counting alone is not enough: under a cool light magenta and purple each still found two regions,
   some of them the other's.)

Gains are per BGR channel, scaled so the white keeps its brightness (B + G + R), applied with a lookup table
(:func:`apply_gains`, about 0.5 ms per 640x480 frame).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..bundles.colors import ColorModel

#: percentiles of brightness above which a candidate white is looked for
BRIGHT_PERCENTILES = (99.5, 98.0, 95.0)
#: a channel at or above this is clipped: its chromaticity is not the light's
CLIPPED = 250
#: a colour region larger than this fraction of the frame is a flood (the suit or a wall taken for a colour)
FLOOD_FRACTION = 0.01
#: a correction with as many complete colours as none must read them this much better (mean wedge distance)
FIT_GAIN = 0.7
#: candidates whose chromaticities are closer than this (rg units) are the same
SAME_WHITE = 0.01


@dataclass
class Balance:
    """The chosen correction: ``gains`` (3,) BGR (None: none applied), the observed ``white`` (3,) BGR it maps
    to the suit's, and the ``scores`` (complete (frame, colour) pairs, fit) of no correction and of each candidate."""

    gains: np.ndarray | None
    white: np.ndarray | None = None
    scores: list[tuple[int, float]] = field(default_factory=list)

    def lut(self) -> np.ndarray | None:
        """(1, 256, 3) uint8 table for ``cv2.LUT`` (None when no correction)."""
        if self.gains is None:
            return None
        x = np.arange(256, dtype=np.float64)[:, None] * self.gains[None, :]
        return np.clip(np.rint(x), 0, 255).astype(np.uint8)[None]

    def describe(self) -> str:
        if self.gains is None:
            return "no white-balance correction (the suit's colours are read as they are)"
        w = self.white[::-1]
        g = self.gains[::-1]
        return (f"white balance corrected: the suit's white appears as RGB ({w[0]:.0f}, {w[1]:.0f}, {w[2]:.0f}) "
                f"(a coloured light or the camera's white balance); gains R {g[0]:.2f}, G {g[1]:.2f}, B {g[2]:.2f}")


def apply_gains(frame: np.ndarray, lut: np.ndarray | None) -> np.ndarray:
    """``frame`` (h, w, 3) BGR uint8 with the per-channel table of :meth:`Balance.lut` applied (as is when None)."""
    return frame if lut is None else cv2.LUT(frame, lut)


def candidate_whites(frames: list[np.ndarray]) -> list[np.ndarray]:
    """Candidate whites (BGR float (3,), 0..255) of the bright unclipped pixels of ``frames`` (see module doc),
    brightest first, near-duplicates dropped."""
    found: list[tuple[float, np.ndarray]] = []
    for frame in frames:
        small = cv2.resize(frame, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA) if min(frame.shape[:2]) >= 64 else frame
        px = small.reshape(-1, 3).astype(np.float32)
        s = px.sum(axis=1)
        ok = (px.max(axis=1) < CLIPPED) & (s > 30.0)
        if ok.sum() < 50:
            continue
        for pct in BRIGHT_PERCENTILES:
            bright = px[ok & (s >= np.percentile(s[ok], pct))]
            if len(bright) < 20:
                continue
            ch = bright[:, 1:] / bright.sum(axis=1, keepdims=True)  # (g, r) chromaticity
            hist, _, _ = np.histogram2d(ch[:, 0], ch[:, 1], bins=100, range=[[0, 1], [0, 1]])
            hist = cv2.GaussianBlur(hist.astype(np.float32), (0, 0), 1.0)
            i, j = np.unravel_index(int(np.argmax(hist)), hist.shape)
            near = (np.abs(ch[:, 0] - (i + 0.5) / 100) < 0.02) & (np.abs(ch[:, 1] - (j + 0.5) / 100) < 0.02)
            if near.sum() >= 10:
                w = bright[near].mean(axis=0).astype(np.float64)
                found.append((float(w.sum()), w))
    found.sort(key=lambda t: -t[0])
    out: list[np.ndarray] = []
    for _, w in found:
        c = w / w.sum()
        if all(np.abs(c - o / o.sum()).max() >= SAME_WHITE for o in out):
            out.append(w)
    return out


def gains_for(white_bgr: np.ndarray, suit_rgb) -> np.ndarray:
    """Per-channel BGR gains mapping ``white_bgr`` to the suit's chromaticity, keeping its brightness (B+G+R)."""
    target = np.asarray(suit_rgb, dtype=np.float64)[::-1]
    g = target / np.maximum(np.asarray(white_bgr, dtype=np.float64), 1.0)
    return g * (float(np.sum(white_bgr)) / float(np.sum(g * white_bgr)))


def read_quality(labels: np.ndarray, idx: np.ndarray, clf, min_area: float) -> tuple[int, float]:
    """How well the colour model reads a label image: ``(complete, fit)``. ``complete``: how many patch colours
    have as many regions (of at least ``min_area`` px²) as joints wear them, none a flood (> FLOOD_FRACTION of
    the image); ``fit``: the mean over colours of their pixels' normalised squared wedge distance (0 = on the
    colour's axis, 1 = on its border; :func:`~tbha_graph.mocap.color.spaces.wedge_distance_sq`). ``idx``: the
    image's chroma table indices (:func:`~tbha_graph.mocap.color.spaces.index_planes`)."""
    model = clf.model
    n, fits = 0, []
    flood = FLOOD_FRACTION * labels.size
    for c, cls in enumerate(model.classes):
        if cls.kind != "chroma":
            continue
        mask = np.equal(labels, c + 1)
        if mask.any():
            fits.append(float(clf.wedge_q[c][idx[mask]].mean()) / clf.D2_SCALE)
        _, _, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8)
        areas = stats[1:, cv2.CC_STAT_AREA]
        if (areas >= min_area).sum() >= len(cls.joints) and not (areas > flood).any():
            n += 1
    return n, (float(np.mean(fits)) if fits else 1.0)


def choose_balance(frames: list[np.ndarray], model: ColorModel, min_area: float = 10.0) -> Balance:
    """The white balance under which the colour model reads the suit's patches best in ``frames`` (BGR uint8
    sample frames, e.g. the take's first second): most complete colours (:func:`read_quality`), then the
    best fit. No correction unless a candidate completes more colours, or as many with a fit better by
    ``FIT_GAIN`` (a video the model already reads well is left exactly as it is)."""
    from .labels import PixelClassifier
    from ..color.spaces import index_planes

    if not frames:
        return Balance(None)
    clf = PixelClassifier(model)
    small = [cv2.resize(f, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA) if min(f.shape[:2]) >= 64 else f for f in frames]
    area = min_area / 4.0 if small[0].shape != frames[0].shape else min_area

    def score(lut) -> tuple[int, float]:
        q = []
        for f in small:
            g = apply_gains(f, lut)
            q.append(read_quality(clf.labels(g), index_planes(model.space, g)[0], clf, area))
        return sum(a for a, _ in q), float(np.mean([b for _, b in q]))

    none = score(None)
    scores = [none]
    best, best_score = Balance(None, scores=scores), none
    for w in candidate_whites(frames):
        g = gains_for(w, model.suit_rgb)
        s = score(Balance(g, w).lut())
        scores.append(s)
        if s[0] > best_score[0] or (s[0] == best_score[0] and s[1] < best_score[1]
                                    and (best.gains is not None or s[1] < FIT_GAIN * none[1])):
            best, best_score = Balance(g, w, scores), s
    return best
