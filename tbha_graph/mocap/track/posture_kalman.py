"""``track.posture_kalman``: posture rules on the start frame, then Kalman prediction and optimal
assignment (the default tracker).

Start frame: the seed's posture rules identify same-coloured patches (:mod:`.posture`). Later frames
(seed: "continuity of motion"): each joint has a constant-velocity ``cv2.KalmanFilter`` (state x, y,
vx, vy in px and px/frame); the candidates of each colour are assigned to that colour's joints by
minimum total distance to the predictions (``scipy.optimize.linear_sum_assignment``), within a gate
that widens with the prediction's uncertainty. A joint left without a candidate is marked not
tracked and keeps its prediction (its velocity fading), so it is never given another patch's
detection; it is picked up again when a candidate reappears within its gate.

``points`` hold the detected centres where tracked (the filter is used for association only;
smoothing is a downstream filter's job).
"""
from __future__ import annotations

import cv2
import numpy as np
from pydantic import Field
from scipy.optimize import linear_sum_assignment

from ...core.node import node
from ...core.types import Json
from ..color.model import as_color_model
from ..ports import TRACKS2D
from ..segment.detections import DETECTIONS
from ..skeleton import N_JOINTS
from .common import StartParams, check_detections, class_joints, frame_candidates, run_passes, start_frame, tracks_bundle

_INF = 1e9


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
        0.8, ge=0, le=1, description="a lost joint's predicted velocity is multiplied by this every frame"
    )


class KalmanTracker:
    """Constant-velocity Kalman filters for the 16 joints plus per-colour optimal assignment."""

    def __init__(self, points0: np.ndarray, joints_of: list[list[int]], p: PostureKalmanParams):
        self.joints_of = joints_of
        self.p = p
        q = p.acceleration**2
        Q = np.array([[0.25, 0, 0.5, 0], [0, 0.25, 0, 0.5], [0.5, 0, 1, 0], [0, 0.5, 0, 1]], np.float32) * q
        self.filters = []
        for j in range(N_JOINTS):
            kf = cv2.KalmanFilter(4, 2)
            kf.transitionMatrix = np.array([[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]], np.float32)
            kf.measurementMatrix = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], np.float32)
            kf.processNoiseCov = Q.copy()
            kf.measurementNoiseCov = np.eye(2, dtype=np.float32) * p.measurement_noise**2
            kf.statePost = np.array([[points0[j, 0]], [points0[j, 1]], [0.0], [0.0]], np.float32)
            kf.errorCovPost = np.diag([p.measurement_noise**2] * 2 + [p.gate_px**2 / 4.0] * 2).astype(np.float32)
            self.filters.append(kf)

    def step(self, candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        pred = np.empty((N_JOINTS, 2))
        spread = np.empty(N_JOINTS)
        for j, kf in enumerate(self.filters):
            s = kf.predict()
            pred[j] = s[0, 0], s[1, 0]
            P = kf.errorCovPre
            spread[j] = np.sqrt(float(P[0, 0] + P[1, 1]))
        gate = np.minimum(self.p.max_gate_px, self.p.gate_px + self.p.gate_sigma * spread)
        points = pred.copy()
        tracked = np.zeros(N_JOINTS, bool)
        for c, joints in enumerate(self.joints_of):
            det = candidates[c]
            if len(det) == 0 or not joints:
                continue
            J = np.asarray(joints)
            cost = np.linalg.norm(pred[J, None, :] - det[None, :, :], axis=2)
            cost = np.where(cost <= gate[J, None], cost, _INF)
            rows, cols = linear_sum_assignment(cost)
            for r, k in zip(rows, cols):
                if cost[r, k] >= _INF:
                    continue
                j = int(J[r])
                self.filters[j].correct(det[k].astype(np.float32).reshape(2, 1))
                points[j] = det[k]
                tracked[j] = True
        for j in np.flatnonzero(~tracked):
            kf = self.filters[j]
            s = kf.statePost
            s[2:] *= self.p.velocity_decay
            kf.statePost = s
        return points, tracked


@node(
    "track.posture_kalman", version=1,
    inputs={"detections": DETECTIONS, "colors": Json(doc="the colour model the segmenter used")},
    outputs={"tracks": TRACKS2D}, params=PostureKalmanParams,
)
def posture_kalman(ctx, detections, colors) -> dict:
    """Identify the 16 joints in the per-colour detections: posture rules on the start T-pose, then
    constant-velocity Kalman prediction and optimal assignment per colour; occluded patches are
    marked not tracked (with their prediction) and recovered when they reappear."""
    p: PostureKalmanParams = ctx.params
    model = as_color_model(colors)
    centres, areas = check_detections(detections)
    joints_of = class_joints(model, detections["colour_names"])
    start, points0 = start_frame(centres, areas, joints_of, p, float(detections["fps"]))
    points, tracked = run_passes(
        frame_candidates(centres), len(centres), start, points0, lambda p0: KalmanTracker(p0, joints_of, p)
    )
    return {"tracks": tracks_bundle(points, tracked, detections)}
