"""``track.posture_kalman``: posture rules on the start frame, then Kalman prediction bounded by the
body and optimal assignment per colour (the default tracker).

Start frame: the seed's posture rules identify same-coloured patches (:mod:`.posture`), left/right
pairs (the seed's suit) by their image order. Later frames (seed: "continuity of motion"):

* each joint has a constant-velocity ``cv2.KalmanFilter`` (x, y, vx, vy in px and px/frame) while it is
  seen or was seen in the last ``lost_after_frames`` frames; its gate widens with its uncertainty;
* a joint unseen for longer is **lost**: it is placed from its parent by the body (:mod:`.body`: its last
  seen offset, rescaled, mirrored when the actor has turned round, never farther than the bone can
  reach), not extrapolated; it is re-acquired by a candidate of its colour that its bones can reach from
  the nearest joint seen in this frame (along the bones), nearest to where that joint puts it. Left/right
  twins with nothing seen within two bones of either, while the torso is hidden, hang from a joint seen within
  :data:`LONG_BONES` (the head), and take a blob only when it is clearly nearer one twin's expected place
  both with their offsets as last seen and mirrored (the facing may have changed unseen); otherwise they
  wait (their identity would be a guess); the torso takes the candidate nearest to where the body last
  had it;
* the candidates of each colour are assigned to that colour's joints globally
  (``scipy.optimize.linear_sum_assignment``; cost = distance over the joint's gate, with "not visible"
  as an option costing one gate), classes in the order of the body tree so parents are placed first;
  a left/right pair attached to the torso (shoulders, hip joints) that comes back after a loss is
  ordered by the body's facing (facing the camera, left on the image's right; back turned, left on
  the left; the chest patch on the suit's front tells which);
* every untracked point is finally brought within reach of its tracked neighbours
  (:meth:`.body.BodyBounds.settle`): no joint is placed where its bones cannot reach.

``points`` hold the detected centres where tracked (the filter is used for association only; smoothing
is a downstream filter's job). ``doubtful`` (n,) uint8 flags each frame whose labelling is doubtful
(bits of :data:`.common.DOUBT`): fewer than ``min_patches`` patches tracked, at least
``doubt_lost_joints`` joints lost, an ambiguous identity (a same-coloured pair either way about as good,
decided by the facing, or left/right twins re-acquired together when either blob could have been
either: flagged until they are lost again), or tracked patches far (median > ``residual_px``) from
their predictions.
"""
from __future__ import annotations

import cv2
import numpy as np
from pydantic import Field

from ...core.errors import NodeError
from ...core.node import node
from ..bundles.colors import as_color_model
from ..ports import COLORS, DETECTIONS, TRACKS2D
from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS, PARENTS
from .body import TORSO_MIRRORS, BodyBounds
from ..tpose import find_tpose
from ..bundles.detections import check_detections
from .common import (DOUBT, StartParams, class_joints, frame_candidates, run_passes, start_frame,
                     tracks_bundle)

HEAD, CHEST, ROOT = JOINT_INDEX["head"], JOINT_INDEX["chest"], JOINT_INDEX["hips"]
TORSO = frozenset(JOINT_INDEX[n] for n in ("hips", "chest", "neck"))
ROOT_CHILDREN = tuple(JOINT_INDEX[n] for n in ("chest", "left_hip", "right_hip"))

_INF = 1e9
#: two lost left/right twins leave a blob when the body expects one of them less than this much nearer (as a
#: fraction of the nearer one's distance; at least a quarter gate): their expected places, from offsets seen
#: before the loss, are too stale to choose between closer calls
TWIN_MARGIN = 0.5
#: two lost left/right twins with no joint seen within two bones of either, while no torso patch (hips, chest,
#: neck) is seen (the back turned, a crouch), are re-acquired from the nearest joint seen within this many bones
#: (the head, for an arm's patch)
LONG_BONES = 5
#: ... by a blob nearer one twin's expected place than the other's by at least this many shoulder widths (at
#: the body's scale) and by TWIN_MARGIN, both with the offsets as last seen and mirrored (the body's facing is
#: stale while the torso is hidden); the nearer one as last seen takes it
LONG_MARGIN = 0.25


def _twins_close(dist: np.ndarray, floor_px: float) -> np.ndarray:
    """(k,) bool: blobs two lost twins are about as near to, ``dist`` (2, k) px from where each is expected:
    closer than ``floor_px`` or :data:`TWIN_MARGIN` of the nearer distance (inf - inf: not comparable)."""
    with np.errstate(invalid="ignore"):
        return np.abs(dist[0] - dist[1]) < np.maximum(floor_px, TWIN_MARGIN * np.minimum(dist[0], dist[1]))


class PostureKalmanParams(StartParams):
    gate_px: float = Field(
        20.0, gt=0, description="association gate of a joint seen in the previous frame", json_schema_extra={"unit": "px"}
    )
    gate_sigma: float = Field(
        3.0, ge=0, description="the gate widens by this many standard deviations of the prediction's uncertainty"
    )
    max_gate_px: float = Field(
        160.0, gt=0, description="widest gate (a joint lost for long)", json_schema_extra={"unit": "px"}
    )
    acceleration: float = Field(
        2.0, gt=0, description="process noise: standard deviation of a joint's acceleration",
        json_schema_extra={"unit": "px/frame²"},
    )
    measurement_noise: float = Field(
        1.0, gt=0, description="standard deviation of a detected centre", json_schema_extra={"unit": "px"}
    )
    velocity_decay: float = Field(
        0.8, ge=0, le=1, description="an unseen joint's predicted velocity is multiplied by this every frame"
    )
    lost_after_frames: int = Field(
        4, ge=0, description="a joint unseen for longer is lost: placed from its parent by the body, re-acquired "
                             "by any candidate its bones can reach", json_schema_extra={"unit": "frame"},
    )
    min_patches: int = Field(
        10, ge=0, le=15, description="frames with fewer of the 15 patches tracked are reported doubtful"
    )
    doubt_lost_joints: int = Field(
        3, ge=1, le=16, description="frames with at least this many lost joints are reported doubtful (one patch "
                                    "hidden for a while is normal in a side view)"
    )
    residual_px: float = Field(
        12.0, gt=0, description="frames whose tracked patches are this far (median) from their predictions are "
                                "reported doubtful", json_schema_extra={"unit": "px"},
    )
    require_tpose: bool = Field(
        False, description="the take must open with a T-pose facing the camera in its first tpose_seconds "
                          "(tbha_graph.mocap.tpose); false: track without one (then give the camera and bones)"
    )
    tpose_seconds: float = Field(3.0, gt=0, description="where the opening T-pose is looked for", json_schema_extra={"unit": "s"})


class KalmanTracker:
    """Constant-velocity Kalman filters for the 16 joints, bounded by the body, plus per-colour optimal
    assignment with a "not visible" option (module docstring)."""

    def __init__(self, points0: np.ndarray, joints_of: list[list[int]], p: PostureKalmanParams):
        self.joints_of = joints_of
        self.p = p
        points0 = np.asarray(points0, dtype=np.float64)
        q = p.acceleration**2
        Q = np.array([[0.25, 0, 0.5, 0], [0, 0.25, 0, 0.5], [0.5, 0, 1, 0], [0, 0.5, 0, 1]], np.float32) * q
        self.filters = []
        for j in range(N_JOINTS):
            kf = cv2.KalmanFilter(4, 2)
            kf.transitionMatrix = np.array([[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]], np.float32)
            kf.measurementMatrix = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], np.float32)
            kf.processNoiseCov = Q.copy()
            kf.measurementNoiseCov = np.eye(2, dtype=np.float32) * p.measurement_noise**2
            self._reset(kf, points0[j])
            self.filters.append(kf)
        self.body = BodyBounds(points0, joints_of)
        self.last = points0.copy()
        self.unseen = np.zeros(N_JOINTS, np.int64)  # frames since each joint was last tracked
        self.doubt = 0  # why the last frame's labelling is doubtful (bits of common.DOUBT)
        self.guessed: set[frozenset[int]] = set()  # left/right twins whose identities were re-acquired by a guess

    def start_unseen(self, joints: list[int]) -> None:
        """``joints`` were not seen in the start frame (their points0 are the T-pose template's guess): they start
        lost, so they are re-acquired only where their bones put them and never take a followed patch's blob."""
        self.unseen[list(joints)] = self.p.lost_after_frames + 1

    def _reset(self, kf, xy) -> None:
        kf.statePost = np.array([[xy[0]], [xy[1]], [0.0], [0.0]], np.float32)
        kf.errorCovPost = np.diag([self.p.measurement_noise**2] * 2 + [self.p.gate_px**2 / 4.0] * 2).astype(np.float32)

    def step(self, candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """One frame: ``candidates[c]`` (k, 2) px or (k, 3) px, px² (with the blob areas) of class ``c``;
        returns ``points`` (16, 2) px and ``tracked`` (16,); sets ``doubt``."""
        from scipy.optimize import linear_sum_assignment  # 0.5 s to import: only when a take is tracked

        p = self.p
        body = self.body
        kf_pred = np.empty((N_JOINTS, 2))
        spread = np.empty(N_JOINTS)
        for j, kf in enumerate(self.filters):
            s = kf.predict()
            kf_pred[j] = s[0, 0], s[1, 0]
            P = kf.errorCovPre
            spread[j] = np.sqrt(float(P[0, 0] + P[1, 1]))
        lost = self.unseen > p.lost_after_frames
        points = np.full((N_JOINTS, 2), np.nan)
        unc = np.zeros(N_JOINTS)  # px: how far each joint's point of this frame may be off
        tracked = np.zeros(N_JOINTS, bool)
        doubt = 0
        residuals = []
        done = np.zeros(N_JOINTS, bool)

        def parent_of(j: int) -> tuple[np.ndarray | None, float]:
            par = int(PARENTS[j])
            if par < 0:
                return None, 0.0
            if done[par]:
                return points[par], unc[par]
            if lost[par]:  # its class comes later: its last point, uncertain by its own reach
                return self.last[par], body.reach(par) + p.gate_px
            return kf_pred[par], min(p.max_gate_px, p.gate_sigma * spread[par])

        # joints seen, to anchor lost ones: placed in this frame, else tracked in the previous one
        seen = {j: (kf_pred[j], p.gate_px) for j in range(N_JOINTS) if self.unseen[j] == 0}
        merged: set[int] = set()  # joints whose patch merged with a same-coloured one in this frame
        head_area = None  # px² of the head's blob, when tracked
        for c in body.class_order:
            J = self.joints_of[c]
            if not J:
                continue
            det = candidates[c]
            det_area = det[:, 2] if det.ndim == 2 and det.shape[1] == 3 else None  # (k,) px², when given
            det = det[:, :2]
            m, k = len(J), len(det)
            pred = np.empty((m, 2))
            gate = np.empty(m)
            anchor = [parent_of(j) for j in J]
            mirrored = m == 2 and len({JOINT_NAMES[j].split("_", 1)[-1] for j in J}) == 1  # a left/right twin pair
            # costs are distances over the joint's gate (<= 1 inside it); "not visible" costs 1 for every joint
            cost = np.full((m, k + m), _INF)
            cost[np.arange(m), k + np.arange(m)] = 1.0
            expected_dist = np.full((m, k), np.inf)  # lost joints: px from where the body expects them
            far = False  # lost twins anchored through a long chain: the body's facing may be stale there
            flipped_dist = np.full((m, k), np.inf)  # ... so px from where they would be with the other facing
            for r, j in enumerate(J):
                P, u = anchor[r]
                if not lost[j]:
                    pred[r] = kf_pred[j]
                    gate[r] = min(p.max_gate_px, p.gate_px + p.gate_sigma * spread[j])
                    if k:
                        dist = np.linalg.norm(det - pred[r], axis=1)
                        cost[r, :k] = np.where(dist <= gate[r], dist / gate[r], _INF)
                    continue
                if j == ROOT:  # from a torso joint placed in this frame, else where it was
                    near = [c2 for c2 in ROOT_CHILDREN if done[c2] and tracked[c2]]
                    pred[r] = (points[near[0]] - body.offset_now(near[0])) if near else self.last[j]
                else:
                    pred[r] = body.predict_from_parent(j, P, self.last[j], u)
                if not k:
                    continue
                found = body.anchor(j, seen)
                if (found is None and mirrored and lost[J[1 - r]] and j not in TORSO and not TORSO & seen.keys()
                        and body.anchor(J[1 - r], seen) is None):
                    found = body.anchor(j, seen, max_bones=LONG_BONES)
                    if found is not None:
                        far = True
                        flipped = body.anchor(j, seen, max_bones=LONG_BONES, facing=-body.facing)[2]
                        flipped_dist[r] = np.linalg.norm(det - flipped, axis=1)
                if found is not None:  # re-acquisition: a candidate its bones can reach from the nearest
                    point, reach, expected = found  # joint seen (along the bones), near where they put it
                    dist = np.linalg.norm(det - expected, axis=1)
                    ok = np.linalg.norm(det - point, axis=1) <= reach
                    norm = reach + p.gate_px
                elif j in TORSO or not mirrored or not lost[J[1 - r]]:
                    # nothing seen to hang from (a torso seen again after a turn; a patch whose colour no mirror
                    # twin wears, or whose twin is followed, so a second blob can only be this one): the
                    # nearest to where the body had it
                    dist = np.linalg.norm(det - pred[r], axis=1)
                    ok = dist <= p.max_gate_px
                    norm = p.max_gate_px
                else:  # a left/right patch with nothing seen to hang from: either side is a guess; wait
                    continue
                # a lost joint's candidate costs more than a followed one's (0.5..1): it never steals one
                cost[r, :k] = np.where(ok, 0.5 + 0.45 * np.minimum(dist / norm, 1.0), _INF)
                expected_dist[r] = dist
            # facing for a torso mirror pair: the chest patch (front of the suit) seen -> facing the camera;
            # lost while the pair comes back -> the back is turned; else as last seen
            facing = None if not done[CHEST] else (
                1.0 if tracked[CHEST] else (-1.0 if lost[CHEST] and all(lost[J]) else None))
            if mirrored and k and frozenset(J) in TORSO_MIRRORS:
                # a left/right pair on the torso: while its middle patch (chest, hips) is seen, the left one
                # is on the image's right of it facing the camera, on its left with the back turned
                mid = int(PARENTS[J[0]])
                if done[mid] and tracked[mid]:
                    facing_now = body.facing if facing is None else facing
                    for r, j in enumerate(J):
                        side = 1.0 if JOINT_NAMES[j].startswith("left") else -1.0
                        wrong_side = facing_now * side * (det[:, 0] - points[mid, 0]) < -p.measurement_noise * 2
                        cost[r, :k] = np.where(wrong_side, _INF, cost[r, :k])
            rows, cols = linear_sum_assignment(cost)
            got = {int(r): int(col) for r, col in zip(rows, cols) if col < k and cost[r, col] < _INF}
            if m == 2 and k >= 1 and not lost[J[0]] and not lost[J[1]] and len(got) < 2:
                # two same-coloured patches seen last frame, one blob within both gates: merged (crossing or
                # touching). Its centre is neither: both keep their constant-velocity predictions
                both = (cost[0, :k] < _INF) & (cost[1, :k] < _INF)
                if both.any() and np.linalg.norm(pred[0] - pred[1]) < gate[0] + gate[1]:
                    got = {r: col for r, col in got.items() if not both[col]}
                    merged.update(J)
                    doubt |= DOUBT["ambiguous identity"]
            if m == 2 and k >= 1 and lost[J[0]] and lost[J[1]]:
                # both lost: a blob either could be, about as well, is left until they can be told apart
                close = _twins_close(expected_dist, 0.25 * p.gate_px)
                if far:  # through a long chain the facing may be stale: a blob near the middle either way waits
                    floor = LONG_MARGIN * body.width0 * body.scale
                    close |= _twins_close(expected_dist, floor) | _twins_close(flipped_dist, floor)
                both = (cost[0, :k] < _INF) & (cost[1, :k] < _INF) & close
                if both.any():
                    got = {r: col for r, col in got.items() if not both[col]}
                    doubt |= DOUBT["ambiguous identity"]
            if k >= 2 and len(J) == 2:
                got, ambiguous = body.resolve_pair(J, det, got, cost, lost, facing)
                if ambiguous:
                    doubt |= DOUBT["ambiguous identity"]
            if mirrored and lost[J[0]] and lost[J[1]] and got:
                # twins both coming back: if a blob they took could have been the other's, which is which
                # was a guess (nothing tells left from right here); flagged until they are lost again
                if any(cost[1 - r, col] < _INF for r, col in got.items()):
                    self.guessed.add(frozenset(J))
            for r, j in enumerate(J):
                if r in got and j == HEAD and det_area is not None:
                    head_area = float(det_area[got[r]])
                if r in got:
                    points[j] = det[got[r]]
                    tracked[j] = True
                    seen[j] = (points[j], 0.0)
                    if not lost[j]:
                        residuals.append(float(np.linalg.norm(det[got[r]] - kf_pred[j])))
                else:
                    P, u = anchor[r]
                    points[j], unc[j] = body.bounded(j, pred[r], P, u, self.last[j], lost[j])
                    seen.pop(j, None)
                    if not lost[j]:
                        unc[j] = max(unc[j], min(p.max_gate_px, p.gate_sigma * spread[j]))
                done[j] = True
        body.settle(points, tracked)
        body.observe(points, tracked, head_area)
        for j, kf in enumerate(self.filters):
            if tracked[j]:
                if lost[j]:
                    self._reset(kf, points[j])
                else:
                    kf.correct(points[j].astype(np.float32).reshape(2, 1))
            else:
                s = kf.statePost
                if j not in merged:  # a merged patch keeps moving as it did
                    s[2:] *= p.velocity_decay
                if self.unseen[j] + 1 > p.lost_after_frames:  # lost: the filter follows the body's estimate
                    s[0, 0], s[1, 0] = points[j]
                    s[2:] = 0.0
                kf.statePost = s
        self.unseen = np.where(tracked, 0, self.unseen + 1)
        self.guessed = {pair for pair in self.guessed if not all(self.unseen[j] > p.lost_after_frames for j in pair)}
        if self.guessed:
            doubt |= DOUBT["ambiguous identity"]
        self.last = points.copy()
        patched = [j for j in range(N_JOINTS) if j != HEAD]
        if tracked[patched].sum() < p.min_patches:
            doubt |= DOUBT["few patches"]
        if (self.unseen > p.lost_after_frames).sum() >= p.doubt_lost_joints:
            doubt |= DOUBT["lost joints"]
        if residuals and float(np.median(residuals)) > p.residual_px:
            doubt |= DOUBT["high residual"]
        self.doubt = doubt
        return points, tracked


@node(
    "track.posture_kalman", version=2,
    inputs={"detections": DETECTIONS, "colors": COLORS},
    outputs={"tracks": TRACKS2D}, params=PostureKalmanParams,
)
def posture_kalman(ctx, detections, colors) -> dict:
    """Identify the 16 joints in the per-colour detections: posture rules on the start T-pose, then
    constant-velocity Kalman prediction bounded by the body and optimal assignment per colour; occluded
    patches are marked not tracked (placed on the body) and re-acquired when they reappear; doubtful
    frames are flagged."""
    p: PostureKalmanParams = ctx.params
    model = as_color_model(colors)
    centres, areas = check_detections(detections)
    joints_of = class_joints(model, detections["colour_names"])
    start, points0, unseen = start_frame(centres, areas, joints_of, p, float(detections["fps"]))
    points, tracked, doubt = run_passes(
        frame_candidates(centres, areas), len(centres), start, points0, lambda p0: KalmanTracker(p0, joints_of, p),
        unseen,
    )
    if p.require_tpose:
        check_opening_tpose(ctx, points, tracked, float(detections["fps"]), p.tpose_seconds)
    return {"tracks": tracks_bundle(points, tracked, detections, doubt)}


def check_opening_tpose(ctx, points, tracked, fps: float, seconds: float) -> None:
    """NodeError with the way out unless the tracks open with a T-pose (:func:`find_tpose`)."""
    found = find_tpose(points, tracked, fps, seconds=seconds, max_untracked=1)  # one washed-out patch (posture.py)
    if found is None:
        raise NodeError(
            f"no T-pose facing the camera in the first {seconds:g} s of the take (arms level and out, legs straight): "
            f"the patches' labels, the camera and the bones all start from it, so the result would be unreliable",
            hint="start at the T-pose (--set decode.start=FRAME, plus truth.start=FRAME when scoring a render), or film "
                 "one (docs/capture.md); to track a take that has none: --set track.require_tpose=false, and give the "
                 "camera (--var focal_px=F) and the measured bones (--set body.path=my_body.yaml)")
    ctx.log(f"T-pose at frames {found[0]}-{found[1]}")
