"""Node ``io.mediapipe_world``: 3D motion from the world landmarks of a MediaPipe Pose file.

The file layouts accepted are documented in :mod:`tbha_graph.mocap.io.mediapipe_keypoints`.
"""
from __future__ import annotations

import numpy as np
from pydantic import Field

from ...core.errors import NodeError
from ...core.node import node
from ..ports import MOTION
from ..skeleton import JOINT_NAMES
from .keypoint_layouts import MEDIAPIPE_POSE, TorsoFractions, fill_untracked, joints16_from_landmarks
from .mediapipe_keypoints import MediaPipeParams, MediaPipeTake, read_mediapipe


class MediaPipeWorldParams(MediaPipeParams):
    root_height: float = Field(0.95, ge=0, le=3, description="height added to the hips-centred world landmarks", json_schema_extra={"unit": "m"})


#: MediaPipe world axes (x right, y down, z away from the camera) -> project world (y up, facing +z).
MEDIAPIPE_TO_WORLD = np.diag([1.0, -1.0, -1.0])


def motion_from_mediapipe(take: MediaPipeTake, fps: float, threshold: float = 0.5, root_height: float = 0.95,
                          fractions: TorsoFractions | None = None, where: str = "MediaPipe file") -> dict[str, np.ndarray]:
    """A MOTION bundle (metres, project world frame) from a take's world landmarks."""
    if take.world is None:
        raise NodeError(f"{where}: the file has no world landmarks",
                        hint="save results.pose_world_landmarks too (JSON 'world_landmarks' or CSV world_x/world_y/world_z)")
    w = take.world
    detected = ~np.isnan(w).all(axis=(1, 2))
    if not detected.any():
        raise NodeError(f"{where}: no frame has world landmarks")
    xyz = np.where(detected[:, None, None], w[..., :3], 0.0) @ MEDIAPIPE_TO_WORLD.T
    vis = np.where(detected[:, None], w[..., 3], 0.0)
    joints, conf = joints16_from_landmarks(xyz, vis, MEDIAPIPE_POSE, fractions, threshold)
    tracked = conf >= threshold
    joints = fill_untracked(joints, tracked, np.repeat(detected[:, None], joints.shape[1], axis=1))
    joints[..., 1] += root_height
    return {"joints": joints, "fps": np.array(fps), "tracked": tracked, "joint_names": np.array(JOINT_NAMES)}


@node("io.mediapipe_world", version=1, outputs={"motion": MOTION}, params=MediaPipeWorldParams)
def mediapipe_world(ctx):
    """3D motion (metres, y up) from the world landmarks of a MediaPipe Pose keypoint file (.json or .csv)."""
    p = ctx.params
    take = read_mediapipe(p.path)
    fps = p.fps or take.fps
    if not fps:
        raise NodeError(f"{p.path}: the file gives no fps", hint="set the param: --set <node>.fps=30")
    return {"motion": motion_from_mediapipe(take, float(fps), p.threshold, p.root_height, p, str(p.path))}
