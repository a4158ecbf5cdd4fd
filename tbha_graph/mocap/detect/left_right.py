"""Consistent left/right labels for detector landmarks.

A pose detector labels each landmark as the person's left or right from the look of the person. On a person
whose face it cannot see (a faceless mannequin, a back view, a side view) MediaPipe often takes the person to
face the other way and swaps left and right for a whole stretch of frames: on the bundled sample it does so
in 141 of 210 frames, T-pose included. A swap moves every left landmark to where the right one was, a jump of
a shoulder's width in the image, while real limbs move continuously.

:func:`consistent_sides` re-decides the labels per *group* of mirror landmark pairs (the arms with the
shoulders and hands, the legs with the hips and feet, the face) as a Viterbi path over the frames: per group
state 0 keeps the detector's labels, state 1 swaps them (arms and legs decided together, four states, with
a cost for a torso whose shoulders and hips face opposite ways). The cost of a path is the image distance each
landmark moves from the previous frame, so the path that moves the limbs least wins; the first frame's state
is the one that puts the person's left on the image's right (the take opens facing the camera, as the
solver needs anyway) — or, with ``start="detector"``, the detector's own labels. Given a ``reference`` that
knows the sides (a suit tracker's left and right patches), each frame's states also cost how much farther their
landmarks are from it than the other state's, and that decides instead of the opening: on the 15 suit renders of
``bench/solver_sweep.py`` (Pose where no torso patch is seen, 1304 frames) the wrong groups (arms 465, legs 468)
went to 20 and 26 (``python bench/mediapipe_sides.py --suit``).
"""
from __future__ import annotations

import numpy as np

from ..io.keypoint_layouts import MEDIAPIPE_POSE, Layout


#: the groups of mirror pairs whose labels are decided together
GROUPS = ("arms", "legs", "face")
#: :func:`feet_facing_cost`: path cost (pixels) per pixel the toes lie below the heels (or above them) beyond
#: ``FEET_DEAD`` x the torso's image length, at most ``FEET_CAP`` x it, for a state whose labels face the other way;
#: a state's facing is ``tanh(labelled torso width / (FEET_WIDTH_SCALE x torso length))`` (0 side-on)
FEET_WEIGHT = 2.0
FEET_DEAD = 0.1
FEET_CAP = 0.2
FEET_WIDTH_SCALE = 0.1


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


def _viterbi(step_cost: np.ndarray, unary: np.ndarray) -> np.ndarray:
    """Cheapest state path: ``step_cost (m-1, K, K)`` cost of (state at t, state at t+1), ``unary (m, K)``.
    Returns ``(m,)`` int."""
    m, K = unary.shape
    acc = unary[0].astype(np.float64).copy()
    back = np.zeros((m, K), dtype=np.int64)
    for t in range(1, m):
        tot = acc[:, None] + step_cost[t - 1]  # (from, to)
        back[t] = np.argmin(tot, axis=0)
        acc = tot[back[t], np.arange(K)] + unary[t]
    path = np.empty(m, dtype=np.int64)
    path[-1] = int(np.argmin(acc))
    for t in range(m - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


def _group_states(P: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """``(m, 2, 2k, 2)``: the group's landmarks as labelled (state 0) and swapped (state 1)."""
    li, ri = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    keep = np.concatenate([P[:, li], P[:, ri]], axis=1)
    flip = np.concatenate([P[:, ri], P[:, li]], axis=1)
    return np.stack([keep, flip], axis=1)


def _motion_cost(S: np.ndarray) -> np.ndarray:
    """``(m-1, 2, 2)``: how far the group's landmarks move from frame to frame for each pair of states."""
    d = np.linalg.norm(S[1:, None, :] - S[:-1, :, None], axis=-1)  # (m-1, from, to, 2k)
    return np.nan_to_num(d, nan=0.0).sum(axis=-1)


def _anchor_cost(S: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``(m, 2)``: per frame and state the image distance of the group's landmarks ``S`` ``(m, 2, 2k, 2)`` from the
    reference points ``R`` ``(m, 2k, 2)`` (the same landmarks, NaN where unknown), less the smaller of the two: 0
    for the state nearer the reference, the margin by which the other is farther for it (about 0 side-on, where
    the reference cannot tell the sides apart)."""
    d = np.nan_to_num(np.linalg.norm(S - R[:, None], axis=-1), nan=0.0).sum(axis=-1)
    return d - d.min(axis=1, keepdims=True)


def feet_facing_cost(P: np.ndarray, layout: Layout, weight: float = FEET_WEIGHT) -> np.ndarray | None:
    """``(m, 4)`` cost of each arms x legs state (``2 * arms_swapped + legs_swapped``) from the feet, or None when
    the layout has no heels and toes. ``P`` ``(m, L, 2)`` image landmarks in pixels (y down).

    Feet point forwards, and a camera above the floor sees the nearer end of a foot lower in the image: the toes
    below the heels when the person faces the camera, above them with the back to it. Which way the person faces
    is thus read without the labels (the mean of both feet's toe-minus-heel image height does not change when left
    and right are exchanged), and a state whose labelled torso (the person's left on the image's right = facing
    the camera) faces the other way pays ``weight`` x that offset beyond a dead zone of :data:`FEET_DEAD` x the
    torso's image length (a foot lifted in a stride, a camera at hip height: a few pixels either way), capped at
    :data:`FEET_CAP` x it, times how squarely the state faces (``tanh`` of the labelled shoulder plus hip width
    over :data:`FEET_WIDTH_SCALE` x the torso length: side-on, nothing). The detector's own heels and toes carry
    its idea of the facing too, but less than its labels do. On ``bench/mediapipe_sides.py``'s seven renders
    (MediaPipe's 33 landmarks against the truth's joints) the frames with the arms' / legs' labels wrong went
    from 339 to 29 (the fast spin 83 / 83 -> 1 / 1, 131_01's low camera 73 / 77 -> 8 / 5, the hop 7 / 6 -> 1 / 3,
    the others unchanged). How far that holds: without the dead zone (or with 0.03-0.06) the spin and the hop
    are fixed but 131_01 only to 64 / 59, and the sample's first 90 frames (its walk towards the camera, toes
    3-5 px above the heels in mid-stride) went wrong for 19 frames; dead zones 0.08-0.12 with weight 2-4 all
    give the 29, weight 1 gives 138."""
    names = ("left_foot_index", "right_foot_index", "left_heel", "right_heel", "left_shoulder", "right_shoulder",
             "left_hip", "right_hip")
    if weight <= 0 or not all(k in layout.landmarks for k in names):
        return None
    lt, rt, lh, rh, ls, rs, lp, rp = (P[:, layout.index(k)] for k in names)
    torso = np.linalg.norm((ls + rs - lp - rp) / 2.0, axis=-1)
    torso = np.nan_to_num(torso, nan=np.nanmedian(torso) if np.isfinite(torso).any() else 1.0)
    toes_below = np.nan_to_num((lt[:, 1] + rt[:, 1] - lh[:, 1] - rh[:, 1]) / 2.0)
    toes_below = np.sign(toes_below) * np.clip(np.abs(toes_below) - FEET_DEAD * torso, 0.0, (FEET_CAP - FEET_DEAD) * torso)
    sdx, hdx = ls[:, 0] - rs[:, 0], lp[:, 0] - rp[:, 0]
    out = np.zeros((P.shape[0], 4))
    for a in (0, 1):
        for leg in (0, 1):
            facing = np.tanh(np.nan_to_num(sdx * (1 - 2 * a) + hdx * (1 - 2 * leg)) / np.maximum(FEET_WIDTH_SCALE * torso, 1e-6))
            out[:, 2 * a + leg] = -weight * facing * toes_below
    return out - out.min(axis=1, keepdims=True)


def consistent_sides(points: np.ndarray, detected: np.ndarray, layout: Layout = MEDIAPIPE_POSE,
                     start: str = "facing_camera", coupling: float = 2.0,
                     reference: np.ndarray | None = None, feet_weight: float = FEET_WEIGHT) -> dict[str, np.ndarray]:
    """Per group (:func:`mirror_pairs`) a bool ``(n,)``: True where the detector's left/right labels are to be
    swapped. ``points`` ``(n, L, 2)`` image landmarks (any unit), ``detected`` ``(n,)`` bool (frames without a
    detection are skipped: the path continues across them).

    The arms (with the shoulders) and the legs (with the hips) are decided together, four states per frame:
    besides how far each group's landmarks move, a frame whose shoulders and hips face opposite ways (the
    labelled left shoulder right of the right one while the left hip is left of the right one: a torso
    turned by half a turn) costs ``coupling`` x the smaller of the two widths in pixels; side-on (one width
    near 0) costs nothing; without a ``reference``, a frame whose labels face the other way than the feet show
    costs :func:`feet_facing_cost` (``feet_weight``; 0: none). The face is decided on its own.

    Measured on the renders (frames with the arms' / legs' labels still wrong, of 99-210, ``python
    bench/mediapipe_sides.py``): the sample 1 / 1, 131_02 far 0 / 2, 131_03 hop 0 / 3, 131_01 low camera 7 / 4
    (MediaPipe misses its T-pose and flips its labels every few frames while the actor stands facing it); on the
    turning renders of the offsets fit 0 / 0, 0 / 4 and 0 / 1 (131_03's fast spin: a whole turn in about a
    second). Before the feet's cue (round 23) 131_01 was 72 / 78 and the spin 80 / 83: continuity alone cannot
    tell a detector that turns its labels round gradually from a person who turns. Without the coupling the
    legs of the far and the hop takes went wrong for 70-100 frames. A prior for facing the camera fixed
    half of 131_01's frames but broke the turning takes (60+ frames each), so there is none; neither is a cost on
    the labelled torso width jumping between frames (round 11: weight 3 fixed half of 131_01 and broke the hop,
    10 fixed the spin and broke another turn). ``python bench/mediapipe_sides.py --solve`` counts the frames
    still wrong per render and what they cost the solve (131_01: PA 108 mm, 72 mm on the truth's labels).

    ``reference`` ``(n, L, 2)`` (same layout and unit as ``points``, NaN where unknown): where another source
    knows which landmark is which (a suit tracker's left and right patches), each state costs how much farther
    its landmarks are from those points than the other state's (:func:`_anchor_cost`), so the labels follow that
    source where it sees the limbs and continuity only bridges where it does not (the actor's back to the camera);
    a reference that knows no landmark on the detected frames leaves the opening's rule in force."""
    pts = np.asarray(points, dtype=np.float64)
    idx = np.flatnonzero(np.asarray(detected, dtype=bool))
    n = pts.shape[0]
    out = {g: np.zeros(n, dtype=bool) for g in GROUPS}
    pairs = mirror_pairs(layout)
    if len(idx) == 0:
        return out
    P = pts[idx]
    m = len(idx)

    def first_cost(S: np.ndarray) -> np.ndarray:
        """(2,) cost of each state on the first frame: the person's left on the image's right (facing the camera)."""
        k = S.shape[2] // 2
        dx = np.nanmean(S[0, :, :k, 0] - S[0, :, k:, 0], axis=-1)  # (2,) left x - right x per state
        if start == "facing_camera":
            return np.where(dx >= 0, 0.0, 1e6)
        return np.array([0.0, 1e6])

    # arms x legs: state = 2 * arms_swapped + legs_swapped
    Sa, Sl = _group_states(P, pairs["arms"]), _group_states(P, pairs["legs"])
    ma, ml = _motion_cost(Sa), _motion_cost(Sl)
    step = ma[:, :, None, :, None] + ml[:, None, :, None, :]  # (m-1, a_from, l_from, a_to, l_to)
    step = step.reshape(m - 1, 4, 4)
    sh = [layout.index("left_shoulder"), layout.index("right_shoulder")]
    hp = [layout.index("left_hip"), layout.index("right_hip")]
    sdx = P[:, sh[0], 0] - P[:, sh[1], 0]
    hdx = P[:, hp[0], 0] - P[:, hp[1], 0]
    unary = np.zeros((m, 4))
    for a in (0, 1):
        for leg in (0, 1):
            s_ = sdx * (1 - 2 * a)
            h_ = hdx * (1 - 2 * leg)
            unary[:, 2 * a + leg] = np.where(s_ * h_ < 0, coupling * np.minimum(np.abs(s_), np.abs(h_)), 0.0)
    ref = None if reference is None else np.asarray(reference, dtype=np.float64)[idx]
    if ref is None or not np.isfinite(ref).any():
        fa, fl = first_cost(Sa), first_cost(Sl)
        unary[0] += (fa[:, None] + fl[None, :]).reshape(4)
        feet = feet_facing_cost(P, layout, feet_weight)  # only without a reference: with a suit's patches the
        if feet is not None:  # wrong groups of the fifteen suit renders went 20 / 26 -> 21 / 32 with it (no dead zone)
            unary += feet
    else:  # the reference decides where it knows the sides, instead of the opening's facing
        ca, cl = (_anchor_cost(S, _group_states(ref, pairs[g])[:, 0]) for S, g in ((Sa, "arms"), (Sl, "legs")))
        unary += (ca[:, :, None] + cl[:, None, :]).reshape(m, 4)
    path = _viterbi(step, np.nan_to_num(unary))
    out["arms"][idx] = path >= 2
    out["legs"][idx] = (path % 2).astype(bool)
    if pairs["face"]:
        Sf = _group_states(P, pairs["face"])
        uf = np.zeros((m, 2))
        uf[0] = first_cost(Sf)
        out["face"][idx] = _viterbi(_motion_cost(Sf), uf).astype(bool)
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
