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

When no frame shows every patch (a patch washed out by a strong light in the whole opening, e.g. the neck
patch facing a bright key light), a frame missing at most ``max_missing`` patches is accepted: the rest T-pose
is fitted to the joints found (scale and offset per image axis) and predicts where the missing ones are; a
colour with fewer candidates than joints gives its candidates to the joints predicted nearest. The missing
joints start at their predicted pixels, not tracked.

Image coordinates: pixels, x right, y down (smaller y = higher).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import permutations

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
    unseen: list[int] = field(default_factory=list)  # joints placed by the T-pose template (max_missing > 0)

    @property
    def ok(self) -> bool:
        return not self.missing and not self.problems


def _rank_joints(joints: list[int]) -> list[int]:
    """Joints ordered top to bottom as in the T-pose seen from the front (ties: image left to right)."""
    rest = tpose()
    # image-left first = the actor's right (-x) first
    return sorted(joints, key=lambda j: (-round(rest[j, 1], 6), rest[j, 0]))


def template_points(pts: np.ndarray) -> np.ndarray | None:
    """The rest T-pose seen from the front ``(16, 2)`` px, fitted (scale and offset per image axis, least
    squares) to the joints of ``pts`` (16, 2) that are not NaN; None when fewer than 4 are."""
    rest = tpose()
    tx, ty = rest[:, 0], -rest[:, 1]  # facing the camera: the actor's +x on the image's right, y down
    have = np.isfinite(pts[:, 0])
    if have.sum() < 4:
        return None
    out = np.empty((N_JOINTS, 2))
    for axis, t in enumerate((tx, ty)):
        A = np.column_stack([t[have], np.ones(int(have.sum()))])
        coef = np.linalg.lstsq(A, pts[have, axis], rcond=None)[0]
        out[:, axis] = coef[0] * t + coef[1]
    return out


def identify(centres: np.ndarray, areas: np.ndarray, class_joints: list[list[int]], min_separation: float,
             max_missing: int = 0) -> PostureResult:
    """Identify the joints in one frame's candidates: ``centres`` (C, K, 2) px (NaN = empty slot),
    ``areas`` (C, K); ``class_joints[c]`` = joint indices wearing class ``c``. With ``max_missing`` > 0, up to
    that many joints without a candidate are placed by the T-pose template (module docstring) and listed in
    ``unseen``."""
    pts = np.full((N_JOINTS, 2), np.nan)
    missing: list[str] = []
    problems: list[str] = []
    short: list[tuple[list[int], np.ndarray]] = []  # colours with fewer candidates than joints, and their candidates
    for c, joints in enumerate(class_joints):
        if not joints:
            continue
        valid = np.flatnonzero(np.isfinite(centres[c, :, 0]))
        if valid.size < len(joints):
            names = " / ".join(JOINT_NAMES[j] for j in joints)
            missing.append(names if valid.size == 0 else f"{names} (only {valid.size} of {len(joints)} same-coloured patches found)")
            short.append((joints, centres[c, valid[np.argsort(-areas[c, valid], kind="stable")]]))
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
    unseen: list[int] = []
    if missing:
        n_missing = sum(len(js) - len(cand) for js, cand in short)
        template = template_points(pts) if n_missing <= max_missing else None
        if template is None:
            return PostureResult(pts, missing, problems)
        for joints, cand in short:  # the candidates go to the joints the template puts nearest
            best = min(permutations(joints, len(cand)),
                       key=lambda js: sum(float(np.linalg.norm(cand[i] - template[j])) for i, j in enumerate(js)))
            for i, j in enumerate(best):
                pts[j] = cand[i]
            unseen += [j for j in joints if j not in best]
        pts[unseen] = template[unseen]
    y = {n: pts[JOINT_INDEX[n], 1] for n in JOINT_NAMES}
    for a, b in zip(_CHAIN[:-1], _CHAIN[1:]):
        if not y[a] < y[b]:
            problems.append(f"{a} is not above {b}")
    low = [n for n in _ARM if not y[n] < y["hips"]]
    if low:
        problems.append(f"{', '.join(low)} not above the hips (arms not raised as in the T-pose)")
    return PostureResult(pts, [], problems, unseen)


def find_start(centres: np.ndarray, areas: np.ndarray, class_joints: list[list[int]], frames: int,
               min_separation: float, max_missing: int = 0) -> tuple[int, np.ndarray, list[int]] | PostureResult:
    """The first of the first ``frames`` frames whose candidates pass :func:`identify`:
    ``(row, points (16, 2), [])``; failing that, with ``max_missing`` > 0, the first passing with the fewest
    joints placed by the T-pose template: ``(row, points, unseen joints)``; otherwise the
    :class:`PostureResult` of the frame that came closest (fewest missing joints, then fewest problems), for
    the error message."""
    best: PostureResult | None = None
    best_key = None
    n = min(frames, len(centres))
    for t in range(n):
        r = identify(centres[t], areas[t], class_joints, min_separation)
        if r.ok:
            return t, r.points, []
        key = (len(r.missing), len(r.problems))
        if best is None or key < best_key:
            best, best_key = r, key
    if max_missing > 0:
        partial: tuple[int, np.ndarray, list[int]] | None = None
        for t in range(n):
            r = identify(centres[t], areas[t], class_joints, min_separation, max_missing)
            if r.ok and (partial is None or len(r.unseen) < len(partial[2])):
                partial = (t, r.points, r.unseen)
        if partial is not None:
            return partial
    assert best is not None
    return best
