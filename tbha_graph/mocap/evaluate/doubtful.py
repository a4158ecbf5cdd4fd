"""Frames whose labelling or 3D result is doubtful, as ranges for ``metrics.json`` (issue 13).

Reasons (bits of a per-frame ``int``; the first four come from the tracker's ``doubtful`` array, see
:data:`tbha_graph.mocap.track.common.DOUBT`):

* ``few patches``: fewer patches tracked than the tracker's ``min_patches``;
* ``lost joints``: at least the tracker's ``doubt_lost_joints`` (3) joints unseen for longer than its
  ``lost_after_frames`` (placed from the body, not measured);
* ``ambiguous identity``: two same-coloured patches could be either joint about as well, or were told
  apart by the body's facing only; or a detector's left/right labels show the torso from behind, so they came
  from continuity alone (``detect.mediapipe_pose``);
* ``high residual``: the tracked patches were far from where the tracker predicted them;
* ``unfilled gap``: some 3D joint neither tracked nor filled (``filter.fill_gaps`` leaves gaps longer
  than its ``max_gap_frames`` unfilled instead of inventing motion);
* ``high reprojection``: the frame's mean reprojection error is above 3 x the take's median and 10 px;
* ``not seen``: nothing of the actor seen (no point tracked, no detector keypoint, no silhouette: out of the
  picture): the solver's motion there is extrapolated from the frames either side (``reconstruct.solve_take``'s
  report ``unseen_ranges``).

``doubtful_ranges``: ``[[first, last, reason], ...]`` (rows of the take, 0-based, ``last`` included),
one list per reason's runs, sorted by ``first``.
"""
from __future__ import annotations

import numpy as np

from ..track.common import DOUBT

REASONS: dict[str, int] = {**DOUBT, "unfilled gap": 16, "high reprojection": 32, "not seen": 64}


def doubtful_bits(n: int, tracks: dict, motion: dict | None = None, reprojection: np.ndarray | None = None,
                  unseen: list | None = None) -> np.ndarray:
    """Per-frame reason bits ``(n,)`` int64 (module docstring) from the tracks' ``doubtful``, the motion's
    ``tracked``/``inferred`` flags, the per-frame reprojection error (px) and the ``unseen`` ranges ``[[first,
    last], ...]`` (rows, ``last`` included) of the solver's report."""
    bits = np.zeros(n, np.int64)
    for first, last in unseen or []:
        bits[max(int(first), 0):max(int(last) + 1, 0)] |= REASONS["not seen"]
    if "doubtful" in tracks and np.shape(tracks["doubtful"]) == (n,):
        bits |= np.asarray(tracks["doubtful"], dtype=np.int64)
    if motion is not None and "inferred" in motion and "tracked" in motion:
        missing = ~(np.asarray(motion["tracked"], dtype=bool) | np.asarray(motion["inferred"], dtype=bool))
        if missing.shape[:1] == (n,):
            bits[missing.reshape(n, -1).any(axis=1)] |= REASONS["unfilled gap"]
    if reprojection is not None:
        r = np.asarray(reprojection, dtype=np.float64).reshape(-1)
        if r.shape == (n,) and np.isfinite(r).any():
            limit = max(3.0 * float(np.nanmedian(r)), 10.0)
            with np.errstate(invalid="ignore"):
                bits[r > limit] |= REASONS["high reprojection"]
    return bits


def doubtful_ranges(bits: np.ndarray) -> list[list]:
    """``[[first, last, reason], ...]`` runs of each reason in ``bits`` (n,), sorted by first frame."""
    bits = np.asarray(bits, dtype=np.int64).reshape(-1)
    out: list[list] = []
    for name, b in REASONS.items():
        on = (bits & b) != 0
        edges = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
        for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            out.append([int(s), int(e - 1), name])
    return sorted(out, key=lambda r: (r[0], r[1], r[2]))


def reason_names(bits: int) -> list[str]:
    """The reasons set in one frame's ``bits``."""
    return [name for name, b in REASONS.items() if int(bits) & b]
