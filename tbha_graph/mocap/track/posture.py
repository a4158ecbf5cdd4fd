"""First-frame identification of same-coloured patches by posture (seed 000, section 1.1).

While the actor stands (not lying, not in a full squat) and holds the start T-pose:

* head above neck above chest above abdomen (hips);
* upper-limb joints above lower-limb joints.

So within one colour, the patch higher in the image belongs to the joint that is higher in the rest
T-pose (:func:`tbha_graph.mocap.skeleton.tpose`); joints at equal T-pose height (a custom suit giving
left and right the same colour) are told apart by the T-pose's left/right: facing the camera, the
actor's left (+x) appears on the image's right. A frame is accepted as the start frame when every
joint has a candidate, the head-neck-chest-hips chain is ordered top to bottom, every arm joint is
above the hips patch, and same-coloured candidates are clearly apart vertically.

Image coordinates: pixels, x right, y down (smaller y = higher).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, tpose

_CHAIN = ("head", "neck", "chest", "hips")
_ARM = ("left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist")


@dataclass
class PostureResult:
    """Outcome for one frame: ``points`` (16, 2) px (NaN = not found), ``missing`` (joints whose patch
    was not found, by name; same-coloured joints named together), ``problems`` (violated rules,
    human-readable); ``ok`` when both are empty."""

    points: np.ndarray
    missing: list[str]
    problems: list[str]

    @property
    def ok(self) -> bool:
        return not self.missing and not self.problems


def _rank_joints(joints: list[int]) -> list[int]:
    """Joints ordered top to bottom as in the T-pose seen from the front (ties: image left to right)."""
    rest = tpose()
    # image-left first = the actor's right (-x) first
    return sorted(joints, key=lambda j: (-round(rest[j, 1], 6), rest[j, 0]))


def identify(centres: np.ndarray, areas: np.ndarray, class_joints: list[list[int]], min_separation: float) -> PostureResult:
    """Identify the joints in one frame's candidates: ``centres`` (C, K, 2) px (NaN = empty slot),
    ``areas`` (C, K); ``class_joints[c]`` = joint indices wearing class ``c``."""
    pts = np.full((N_JOINTS, 2), np.nan)
    missing: list[str] = []
    problems: list[str] = []
    for c, joints in enumerate(class_joints):
        if not joints:
            continue
        valid = np.flatnonzero(np.isfinite(centres[c, :, 0]))
        if valid.size < len(joints):
            names = " / ".join(JOINT_NAMES[j] for j in joints)
            missing.append(names if valid.size == 0 else f"{names} (only {valid.size} of {len(joints)} same-coloured patches found)")
            continue
        # the largest candidates, one per joint, then ordered top to bottom (ties: left to right)
        take = valid[np.argsort(-areas[c, valid], kind="stable")[: len(joints)]]
        cand = centres[c, take]
        ranked = _rank_joints(joints)
        order = np.argsort(cand[:, 1], kind="stable")  # top to bottom...
        heights = [round(tpose()[j, 1], 6) for j in ranked]
        i = 0
        while i < len(ranked):  # ...and within a tier of equal T-pose height (a left/right pair), left to right
            e = i
            while e < len(ranked) and heights[e] == heights[i]:
                e += 1
            tier = order[i:e]
            order[i:e] = tier[np.argsort(cand[tier, 0], kind="stable")]
            i = e
        for j, k in zip(ranked, order):
            pts[j] = cand[k]
        if len(joints) > 1:
            ys = np.sort(cand[:, 1])
            gaps = np.diff(ys)
            rest_y = np.array([round(tpose()[j, 1], 6) for j in joints])
            if len(np.unique(rest_y)) == len(joints) and gaps.min() < min_separation:
                names = ", ".join(JOINT_NAMES[j] for j in joints)
                problems.append(f"same-coloured patches {names} are only {gaps.min():.1f} px apart vertically")
    if missing:
        return PostureResult(pts, missing, problems)
    y = {n: pts[JOINT_INDEX[n], 1] for n in JOINT_NAMES}
    for a, b in zip(_CHAIN[:-1], _CHAIN[1:]):
        if not y[a] < y[b]:
            problems.append(f"{a} is not above {b}")
    low = [n for n in _ARM if not y[n] < y["hips"]]
    if low:
        problems.append(f"{', '.join(low)} not above the hips (arms not raised as in the T-pose)")
    return PostureResult(pts, [], problems)


def find_start(centres: np.ndarray, areas: np.ndarray, class_joints: list[list[int]], frames: int,
               min_separation: float) -> tuple[int, np.ndarray] | PostureResult:
    """The first of the first ``frames`` frames whose candidates pass :func:`identify`:
    ``(row, points (16, 2))``; otherwise the :class:`PostureResult` of the frame that came closest
    (fewest missing joints, then fewest problems), for the error message."""
    best: PostureResult | None = None
    best_key = None
    for t in range(min(frames, len(centres))):
        r = identify(centres[t], areas[t], class_joints, min_separation)
        if r.ok:
            return t, r.points
        key = (len(r.missing), len(r.problems))
        if best is None or key < best_key:
            best, best_key = r, key
    assert best is not None
    return best
