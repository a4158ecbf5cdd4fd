"""``track.nearest``: posture rules on the start frame, then nearest-candidate matching (an alternative
to ``track.posture_kalman``, without prediction).

Each frame, within each colour, joint-candidate pairs are taken greedily by increasing distance from
the joint's last seen position (each joint and each candidate used once), if closer than ``gate_px``.
A joint left without a candidate is marked not tracked and keeps its last seen position. Fast motion
or two same-coloured patches crossing can swap identities: that is what the Kalman tracker is for.
"""
from __future__ import annotations

import numpy as np
from pydantic import Field

from ...core.node import node
from ..bundles.colors import as_color_model
from ..ports import COLORS, DETECTIONS, TRACKS2D
from ..skeleton import N_JOINTS
from ..bundles.detections import check_detections
from .common import StartParams, class_joints, frame_candidates, run_passes, start_frame, tracks_bundle


class NearestParams(StartParams):
    gate_px: float = Field(
        40.0, gt=0, description="largest distance from a joint's last seen position to its candidate",
        json_schema_extra={"unit": "px"},
    )


class NearestTracker:
    """Greedy nearest-candidate matching per colour from the joints' last seen positions."""

    def __init__(self, points0: np.ndarray, joints_of: list[list[int]], p: NearestParams):
        self.last = np.asarray(points0, dtype=np.float64).copy()
        self.joints_of = joints_of
        self.gate = p.gate_px

    def step(self, candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        tracked = np.zeros(N_JOINTS, bool)
        for c, joints in enumerate(self.joints_of):
            det = candidates[c]
            if len(det) == 0 or not joints:
                continue
            J = np.asarray(joints)
            d = np.linalg.norm(self.last[J, None, :] - det[None, :, :], axis=2)
            used_j, used_k = set(), set()
            for flat in np.argsort(d, axis=None):
                r, k = divmod(int(flat), d.shape[1])
                if d[r, k] > self.gate:
                    break
                if r in used_j or k in used_k:
                    continue
                used_j.add(r)
                used_k.add(k)
                self.last[J[r]] = det[k]
                tracked[J[r]] = True
        return self.last.copy(), tracked


@node(
    "track.nearest", version=1,
    inputs={"detections": DETECTIONS, "colors": COLORS},
    outputs={"tracks": TRACKS2D}, params=NearestParams,
)
def nearest(ctx, detections, colors) -> dict:
    """Identify the 16 joints in the per-colour detections: posture rules on the start T-pose, then
    each joint takes the nearest candidate of its colour to where it was last seen (no prediction)."""
    p: NearestParams = ctx.params
    model = as_color_model(colors)
    centres, areas = check_detections(detections)
    joints_of = class_joints(model, detections["colour_names"])
    start, points0, unseen = start_frame(centres, areas, joints_of, p, float(detections["fps"]))
    points, tracked, _ = run_passes(
        frame_candidates(centres), len(centres), start, points0, lambda p0: NearestTracker(p0, joints_of, p),
        unseen,
    )
    return {"tracks": tracks_bundle(points, tracked, detections)}
