"""What the body allows a 2D tracker: where an unseen joint can be, and which side a mirror patch is.

:class:`BodyBounds` is built from the start T-pose's pixels (every bone seen at about its full length,
the actor facing the camera) and kept up to date with the tracked points:

* ``scale``: the body's size in the image relative to the start (torso height and shoulder width,
  whichever is larger: turning shortens the width, bending the height); it shrinks at most 3 % a frame.
  While no torso pair is seen (the back turned), the head blob's area does (its size at scale 1 learnt
  while the torso was seen), by at most 3 % a frame.
* ``reach(j)``: the farthest a joint's patch can be from its parent's patch in the image: the bone's
  start length x ``scale`` x 1.15, plus 0.12 m (both patches sit on the suit, in front of their joints;
  metres -> pixels from the start torso, neck to hips = 0.315 m). No point the tracker outputs is
  farther from its parent's point than that: a joint is never placed where its bones cannot reach. A point
  it places (not measured) is held closer, within the bone as the start showed it x ``scale`` x 1.15
  (:meth:`BodyBounds.placed_reach`: the margin is for blobs anywhere on a patch, not for a guess).
* the last seen offset of each joint from its parent, and the ``facing`` it was seen with (+1 front to
  the camera, -1 back): a lost joint is placed at its parent plus that offset (mirrored left-right when
  the actor has turned round since, shortened to the reach), never extrapolated.
* ``facing``: from the shoulders' order while both are tracked (facing the camera, the actor's left is
  on the image's right; with the back to it, on the left), and +1 whenever the chest patch (on the
  front of the suit) is seen.

A left/right pair wearing one colour (the seed's suit) attached to the torso (shoulders, hip joints) is
re-acquired by that order: when either was lost and both candidates could be either, the left one is
the one on the image's right when facing the camera, on the left with the back to it.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, PARENTS

_INF = 1e9
REACH_SLACK = 1.15
REACH_MARGIN_M = 0.12
TORSO_M = 0.315  # neck to hips of the default body, metres (skeleton.DEFAULT_BONE_LENGTHS chest + neck)
_J = JOINT_INDEX
#: Mirror pairs the facing order tells apart when they share a colour (children of the torso).
TORSO_MIRRORS = {frozenset((_J["left_shoulder"], _J["right_shoulder"])), frozenset((_J["left_hip"], _J["right_hip"]))}


def _depth(j: int) -> int:
    d = 0
    while PARENTS[j] >= 0:
        j = int(PARENTS[j])
        d += 1
    return d


class BodyBounds:
    """Body constraints for one tracking pass (module docstring); ``points0`` (16, 2) px of the start
    T-pose, ``joints_of[c]`` the joints wearing class ``c``."""

    def __init__(self, points0: np.ndarray, joints_of: list[list[int]]):
        p0 = np.asarray(points0, dtype=np.float64)
        par = np.where(PARENTS < 0, 0, PARENTS)
        self.offset = p0 - p0[par]
        self.offset[0] = 0.0
        self.L0 = np.linalg.norm(self.offset, axis=1)
        self.torso0 = max(float(np.linalg.norm(p0[_J["neck"]] - p0[_J["hips"]])), 1.0)
        self.width0 = max(float(np.linalg.norm(p0[_J["left_shoulder"]] - p0[_J["right_shoulder"]])), 1.0)
        self.px_per_m = self.torso0 / TORSO_M
        self.offset_facing = np.ones(N_JOINTS)
        self.offset_scale = np.ones(N_JOINTS)
        self.scale = 1.0
        self.head_ref: float | None = None  # area (px²) of the head's blob at scale 1
        self.facing = 1.0
        # classes whose joints hang lower in the tree come later, so that parents are placed first (the
        # root's class first; then by the shallowest, then the deepest joint; single-patch colours first)
        depths = [[_depth(j) for j in js] or [99] for js in joints_of]
        self.class_order = sorted(range(len(joints_of)),
                                  key=lambda c: (min(depths[c]), max(depths[c]), len(joints_of[c]), c))

    def reach(self, j: int) -> float:
        """Farthest (px) joint ``j``'s patch can be from its parent's patch in the image now."""
        return self.scale * (REACH_SLACK * self.L0[j] + REACH_MARGIN_M * self.px_per_m)

    def offset_now(self, j: int, facing: float | None = None) -> np.ndarray:
        """Joint ``j``'s expected offset from its parent now (last seen, rescaled, mirrored if the actor
        turned round since; ``facing``: +1 / -1 in place of the body's), at most its reach."""
        off = self.offset[j] * (self.scale / self.offset_scale[j])
        if self.offset_facing[j] != (self.facing if facing is None else facing):
            off = off * np.array([-1.0, 1.0])
        n = float(np.linalg.norm(off))
        r = self.reach(j)
        return off * (r / n) if n > r else off

    def anchor(self, j: int, seen: dict[int, tuple[np.ndarray, float]], max_bones: int = 2,
               facing: float | None = None):
        """The nearest joint seen (``seen``: joint -> (point, slack px)) along the bones from ``j``:
        ``(point, reach, pred)`` = its point, how far ``j`` can be from it (reaches along the path plus
        its slack) and where ``j`` is expected (its point plus the offsets along the path, as seen with
        ``facing``, default the body's); None if no seen joint is within ``max_bones`` bones."""
        frontier = [(j, 0.0, np.zeros(2))]
        visited = {j}
        for _ in range(max_bones):
            nxt = []
            for a, reach, off in frontier:
                par = int(PARENTS[a])
                links = ([(par, self.reach(a), -self.offset_now(a, facing))] if par >= 0 else []) + [
                    (c, self.reach(c), self.offset_now(c, facing)) for c in range(N_JOINTS) if PARENTS[c] == a]
                for b, r, o in links:
                    if b in visited:
                        continue
                    visited.add(b)
                    if b in seen:  # the offset from b to j is minus the path's offsets from j to b
                        point, slack = seen[b]
                        return point, reach + r + slack, point - (off + o)
                    nxt.append((b, reach + r, off + o))
            frontier = nxt
        return None

    def predict_from_parent(self, j: int, parent: np.ndarray | None, last: np.ndarray, unc: float) -> np.ndarray:
        """Where a lost joint is expected: its parent plus its last seen offset (module docstring)."""
        if parent is None:
            return np.asarray(last, dtype=np.float64).copy()
        return parent + self.offset_now(j)

    def bounded(self, j: int, pred: np.ndarray, parent: np.ndarray | None, unc_parent: float, last: np.ndarray,
                lost: bool) -> tuple[np.ndarray, float]:
        """An unseen joint's point (its prediction, brought within reach of its parent's point) and
        how far off it may be (px)."""
        if parent is None:
            return np.asarray(pred, dtype=np.float64), 0.0
        v = np.asarray(pred, dtype=np.float64) - parent
        n = float(np.linalg.norm(v))
        r = self.reach(j)
        point = parent + (v * (r / n) if n > r else v)
        return point, unc_parent + (r if lost else 0.0)

    def resolve_pair(self, J: list[int], det: np.ndarray, got: dict[int, int], cost: np.ndarray, lost: np.ndarray,
                     facing: float | None, ambiguity: float = 0.1) -> tuple[dict[int, int], bool]:
        """Check a two-joint colour's assignment ``got`` (row -> candidate); returns it (possibly swapped)
        and whether the identities were ambiguous (both candidates admissible for both joints and the
        two assignments about as good, or decided by the facing order)."""
        if len(got) != 2:
            return got, False
        a, b = got[0], got[1]
        if cost[0, b] >= _INF or cost[1, a] >= _INF:
            return got, False  # only one way is possible
        close = abs((cost[0, a] + cost[1, b]) - (cost[0, b] + cost[1, a])) < ambiguity
        if frozenset(J) in TORSO_MIRRORS and (lost[J[0]] or lost[J[1]]):
            if facing is not None:
                self.facing = facing
            left = 0 if JOINT_NAMES[J[0]].startswith("left") else 1
            facing = self.facing if facing is None else facing
            xl, xr = det[got[left], 0], det[got[1 - left], 0]
            if facing * (xl - xr) < 0:
                return {0: b, 1: a}, True
            return got, True
        return got, close

    def placed_reach(self, j: int, within: float = 0.8) -> float:
        """Farthest (px) a joint the tracker places (not measured) may be from its parent's point, or the parent
        from it: ``within`` x :meth:`reach`, and at most the bone as the start T-pose showed it (patch to patch, so
        its patches' offsets included) x ``scale`` x ``REACH_SLACK``. Reach's margin is for blobs that may be
        anywhere on the suit; a placed point has no such excuse, and on short bones the margin doubles the reach
        (the head to the neck: 26 px seen at the start, 45 px allowed), which put a placed neck beyond what the
        bone allows once the actor had walked away from the camera (``bench/labelling.py`` ``off_body_placed_pct``)."""
        return min(within * self.reach(j), self.scale * REACH_SLACK * float(self.L0[j]))

    def settle(self, points: np.ndarray, tracked: np.ndarray, sweeps: int = 8, within: float = 0.8) -> np.ndarray:
        """Bring untracked joints within :meth:`placed_reach` of their neighbours, in place: each bone longer
        than that is shortened by moving its untracked end(s) (both halfway when both are untracked);
        tracked points never move; what the sweeps leave (a chain pulled from both ends, or far from its one tracked
        end) is settled outwards from the tracked joints. Returns ``points``."""
        for _ in range(sweeps):
            moved = False
            for j in range(1, N_JOINTS):
                par = int(PARENTS[j])
                if tracked[j] and tracked[par]:
                    continue
                v = points[j] - points[par]
                n = float(np.linalg.norm(v))
                r = self.placed_reach(j, within)
                if n <= r or n == 0.0:
                    continue
                excess = v * (1.0 - r / n)
                if tracked[par]:
                    points[j] -= excess
                elif tracked[j]:
                    points[par] += excess
                else:
                    points[j] -= 0.5 * excess
                    points[par] += 0.5 * excess
                moved = True
            if not moved:
                break
        # whatever is left: outwards along the bones from the tracked joints (from the root when none is), each
        # untracked joint brought within reach of the neighbour it is reached from
        done = np.asarray(tracked, dtype=bool).copy()
        if not done.any():
            done[0] = True
        frontier = [int(k) for k in np.flatnonzero(done)]
        while frontier:
            nxt = []
            for a in frontier:
                for b in ([int(PARENTS[a])] if PARENTS[a] >= 0 else []) + [int(c) for c in np.flatnonzero(PARENTS == a)]:
                    if done[b]:
                        continue
                    v = points[b] - points[a]
                    n = float(np.linalg.norm(v))
                    r = self.placed_reach(b if PARENTS[b] == a else a, within)  # the bone between a and b
                    if n > r:
                        points[b] = points[a] + v * (r / n)
                    done[b] = True
                    nxt.append(b)
            frontier = nxt
        return points

    def observe(self, points: np.ndarray, tracked: np.ndarray, head_area: float | None = None) -> None:
        """Update scale, facing and offsets from a frame's points (16, 2), tracked flags (16,) and the
        head blob's area (px², None when not seen). While the torso is seen it sets the scale (and the
        head's area at scale 1 is learnt); while it is not, the head's size does (the dark head looks the
        same size from every side), changing at most 3 % a frame."""
        ls, rs, neck, hips, chest = _J["left_shoulder"], _J["right_shoulder"], _J["neck"], _J["hips"], _J["chest"]
        obs = []
        if tracked[neck] and tracked[hips]:
            obs.append(np.linalg.norm(points[neck] - points[hips]) / self.torso0)
        if tracked[ls] and tracked[rs]:
            dx = float(points[ls, 0] - points[rs, 0])
            obs.append(abs(dx) / self.width0)
            if abs(dx) > 0.3 * self.width0 * self.scale:
                self.facing = 1.0 if dx > 0 else -1.0
        elif tracked[chest]:
            self.facing = 1.0
        if obs:
            self.scale = float(np.clip(max(max(obs), 0.97 * self.scale), 0.2, 5.0))
            if head_area and head_area > 0:
                ref = head_area / self.scale**2
                self.head_ref = ref if self.head_ref is None else 0.9 * self.head_ref + 0.1 * ref
        elif head_area and head_area > 0 and self.head_ref:
            s_head = float(np.sqrt(head_area / self.head_ref))
            self.scale = float(np.clip(s_head, 0.97 * self.scale, 1.03 * self.scale))
        for j in range(1, N_JOINTS):
            par = PARENTS[j]
            if tracked[j] and tracked[par]:
                self.offset[j] = points[j] - points[par]
                self.offset_facing[j] = self.facing
                self.offset_scale[j] = self.scale
