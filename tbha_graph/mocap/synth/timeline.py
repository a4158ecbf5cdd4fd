"""Sampling a motion at arbitrary times (resampling to the video frame rate, motion-blur sub-frames)."""
from __future__ import annotations

import numpy as np


class MotionSampler:
    """Linear interpolation of joint positions ``(n, J, 3)`` recorded at ``fps`` frames/s.

    Time 0 is the first motion frame; times outside ``[0, duration]`` are clamped to the ends.
    """

    def __init__(self, joints: np.ndarray, fps: float):
        self.joints = np.asarray(joints, dtype=np.float64)
        self.fps = float(fps)
        self.duration = (self.joints.shape[0] - 1) / self.fps

    def n_frames(self, fps_out: float) -> int:
        """Number of output frames at ``fps_out`` spanning the motion (first and last frame included)."""
        return int(np.floor(self.duration * fps_out + 1e-6)) + 1

    def at(self, times: np.ndarray) -> np.ndarray:
        """Joint positions ``(len(times), J, 3)`` at ``times`` seconds."""
        f = np.clip(np.asarray(times, dtype=np.float64) * self.fps, 0.0, self.joints.shape[0] - 1)
        i0 = np.minimum(np.floor(f).astype(np.int64), self.joints.shape[0] - 1)
        i1 = np.minimum(i0 + 1, self.joints.shape[0] - 1)
        w = (f - i0)[:, None, None]
        return (1.0 - w) * self.joints[i0] + w * self.joints[i1]
