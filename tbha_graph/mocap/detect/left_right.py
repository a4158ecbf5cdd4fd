"""Consistent left/right labels for detector landmarks.

A pose detector labels each landmark as the person's left or right from the look of the person. On a person
whose face it cannot see (a faceless mannequin, a back view, a side view) MediaPipe often takes the person to
face the other way and swaps left and right for a whole stretch of frames: on the bundled sample it does so
in 141 of 210 frames, T-pose included. A swap moves every left landmark to where the right one was, a jump of
a shoulder's width in the image, while real limbs move continuously.

:func:`consistent_sides` re-decides the labels per *group* of mirror landmark pairs (the arms with the
shoulders and hands, the legs with the hips and feet, the face) as a two-state Viterbi path over the frames:
state 0 keeps the detector's labels, state 1 swaps the group. The cost of a path is the image distance each
landmark moves from the previous frame, so the path that moves the limbs least wins; the first frame's state
is the one that puts the person's left on the image's right (the take opens facing the camera, as the
solver needs anyway) — or, with ``start="detector"``, the detector's own labels.
"""
from __future__ import annotations

import numpy as np

from ..io.keypoint_layouts import MEDIAPIPE_POSE, Layout


#: the groups of mirror pairs whose labels are decided together
GROUPS = ("arms", "legs", "face")


def mirror_pairs(layout: Layout) -> dict[str, list[tuple[int, int]]]:
    """Mirror landmark index pairs ``(left, right)`` of a layout, by group: arms, legs, face."""
    groups = {"arms": ("shoulder", "elbow", "wrist", "pinky", "index", "thumb"),
              "legs": ("hip", "knee", "ankle", "heel", "foot_index"),
              "face": ("eye_inner", "eye", "eye_outer", "ear", "mouth")}
    out: dict[str, list[tuple[int, int]]] = {}
    for g, parts in groups.items():
        pairs = []
        for part in parts:
            a, b = (f"left_{part}", f"right_{part}") if part != "mouth" else ("mouth_left", "mouth_right")
            if a in layout.landmarks and b in layout.landmarks:
                pairs.append((layout.index(a), layout.index(b)))
        out[g] = pairs
    return out


def _viterbi_two(step_cost: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Cheapest state path for two states: ``step_cost (n-1, 2, 2)`` cost of (state at t, state at t+1),
    ``first (2,)`` cost of the first state. Returns ``(n,)`` int."""
    n = step_cost.shape[0] + 1
    acc = first.astype(np.float64).copy()
    back = np.zeros((n, 2), dtype=np.int64)
    for t in range(1, n):
        tot = acc[:, None] + step_cost[t - 1]  # (from, to)
        back[t] = np.argmin(tot, axis=0)
        acc = tot[back[t], [0, 1]]
    path = np.empty(n, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for t in range(n - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


def consistent_sides(points: np.ndarray, detected: np.ndarray, layout: Layout = MEDIAPIPE_POSE,
                     start: str = "facing_camera") -> dict[str, np.ndarray]:
    """Per group (:func:`mirror_pairs`) a bool ``(n,)``: True where the detector's left/right labels are to be
    swapped. ``points`` ``(n, L, 2)`` image landmarks (any unit), ``detected`` ``(n,)`` bool (frames without a
    detection are skipped: the path continues across them)."""
    pts = np.asarray(points, dtype=np.float64)
    idx = np.flatnonzero(np.asarray(detected, dtype=bool))
    n = pts.shape[0]
    out: dict[str, np.ndarray] = {}
    for group, pairs in mirror_pairs(layout).items():
        swap = np.zeros(n, dtype=bool)
        if len(idx) == 0 or not pairs:
            out[group] = swap
            continue
        li, ri = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
        P = pts[idx]
        keep = np.concatenate([P[:, li], P[:, ri]], axis=1)  # (m, 2k, 2) as labelled
        flip = np.concatenate([P[:, ri], P[:, li]], axis=1)  # swapped
        S = np.stack([keep, flip], axis=1)  # (m, 2 states, 2k, 2)
        d = np.linalg.norm(S[1:, None, :] - S[:-1, :, None], axis=-1)  # (m-1, from, to, 2k)
        step = np.nan_to_num(d, nan=0.0).sum(axis=-1)
        if start == "facing_camera":
            # facing the camera, the person's left is on the image's right: left x - right x > 0
            dx = float(np.nanmean(P[0, li, 0] - P[0, ri, 0]))
            first = np.array([0.0, 1e6]) if dx >= 0 else np.array([1e6, 0.0])
        else:
            first = np.array([0.0, 1e6])
        path = _viterbi_two(step, first) if len(idx) > 1 else np.argmin(first)[None]
        swap[idx] = path.astype(bool)
        # frames without a detection follow the previous detected frame
        out[group] = swap
    return out


def apply_sides(landmarks: np.ndarray, swaps: dict[str, np.ndarray], layout: Layout = MEDIAPIPE_POSE) -> np.ndarray:
    """``landmarks`` ``(n, L, C)`` with each group's mirror pairs exchanged on the frames ``swaps`` marks."""
    out = np.array(landmarks, dtype=np.float64, copy=True)
    pairs = mirror_pairs(layout)
    for group, mask in swaps.items():
        if not mask.any():
            continue
        li = np.array([p[0] for p in pairs[group]])
        ri = np.array([p[1] for p in pairs[group]])
        f = np.flatnonzero(mask)
        a, b = out[np.ix_(f, li)].copy(), out[np.ix_(f, ri)].copy()
        out[np.ix_(f, li)], out[np.ix_(f, ri)] = b, a
    return out
