"""Simple synthetic tight-suit frames for tests and benchmarks (not a renderer: see ``synth.*`` for that).

:func:`draw_frame` paints a light-grey stick body (thick bones), the suit's coloured discs at the joint
positions with a specular highlight on each, a dark head disc, a slight blur (the blurred band between
patch and suit) and Gaussian sensor noise. :func:`tpose_points` gives T-pose joint pixels.
All positions are pixels (x, y) from the top-left; frames are BGR uint8 ``(height, width, 3)``.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..camera import Camera
from ..skeleton import BONES, JOINT_INDEX, JOINT_NAMES, PATCHED_JOINTS, bone_lengths_array, tpose
from ..suit import SuitSpec, load_suit

_SHIFT = 4  # cv2 drawing with 1/16 px precision


#: Spread-out proportions for drawn test frames, so that no two drawn discs overlap (the real body's
#: neck and head joints are closer than a patch's diameter at this distance).
TEST_BONES = {"neck": 0.22, "head": 0.15, "left_shoulder": 0.21, "right_shoulder": 0.21, "left_hip": 0.14, "right_hip": 0.14,
              "left_elbow": 0.28, "right_elbow": 0.28, "left_wrist": 0.25, "right_wrist": 0.25}


def tpose_points(width: int = 640, height: int = 480, distance: float = 3.2, focal_px: float = 520.0) -> np.ndarray:
    """The rest T-pose seen from the front: joint pixels ``(16, 2)`` (proportions :data:`TEST_BONES`)."""
    cam = Camera.look_at((0.0, 0.9, distance), (0.0, 0.9, 0.0), focal_px=focal_px, width=width, height=height)
    return cam.project(tpose(bone_lengths_array(TEST_BONES)))


def _pt(p) -> tuple[int, int]:
    return int(round(p[0] * (1 << _SHIFT))), int(round(p[1] * (1 << _SHIFT)))


def draw_frame(
    points: np.ndarray,
    suit: SuitSpec | None = None,
    *,
    width: int = 640,
    height: int = 480,
    radius: float = 8.0,
    head_radius: float = 15.0,
    visible: np.ndarray | None = None,
    highlight: bool = True,
    shade: float = 0.9,
    noise: float = 3.0,
    background: tuple[int, int, int] = (95, 105, 110),
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """A frame with the suit's patches at ``points`` (16, 2) px (``visible`` (16,) bool hides patches)."""
    suit = suit or load_suit()
    rng = rng or np.random.default_rng(0)
    visible = np.ones(len(JOINT_NAMES), bool) if visible is None else np.asarray(visible, bool)
    img = np.empty((height, width, 3), np.uint8)
    img[:] = background
    body = (236, 236, 236)
    for parent, child in BONES:
        if JOINT_NAMES[child] == "head":
            continue
        cv2.line(img, _pt(points[parent]), _pt(points[child]), body, int(2.6 * radius), cv2.LINE_AA, _SHIFT)
    for j in range(len(JOINT_NAMES)):
        if JOINT_NAMES[j] != "head":
            cv2.circle(img, _pt(points[j]), int(1.4 * radius * (1 << _SHIFT)), body, -1, cv2.LINE_AA, _SHIFT)
    h = JOINT_INDEX["head"]
    if visible[h]:
        cv2.circle(img, _pt(points[h]), int(head_radius * (1 << _SHIFT)), (22, 24, 28), -1, cv2.LINE_AA, _SHIFT)
    for name in PATCHED_JOINTS:
        j = JOINT_INDEX[name]
        if not visible[j]:
            continue
        rgb = suit.rgb(suit.patches[name]) * 255.0 * shade
        bgr = tuple(float(v) for v in rgb[::-1])
        cv2.circle(img, _pt(points[j]), int(radius * (1 << _SHIFT)), bgr, -1, cv2.LINE_AA, _SHIFT)
        if highlight:
            hp = points[j] + np.array([-0.3, -0.35]) * radius
            cv2.circle(img, _pt(hp), int(0.3 * radius * (1 << _SHIFT)), (250, 250, 250), -1, cv2.LINE_AA, _SHIFT)
    img = cv2.GaussianBlur(img, (3, 3), 0.7)
    if noise > 0:
        img = np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).astype(np.uint8)
    return img


def write_video(path, frames, fps: float = 30.0, fourcc: str = "mp4v") -> None:
    """Write BGR frames with ``cv2.VideoWriter``: ``"mp4v"`` (lossy, .mp4) or ``"FFV1"`` (lossless, .avi)."""
    frames = list(frames)
    h, w = frames[0].shape[:2]
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h))
    try:
        for f in frames:
            wr.write(f)
    finally:
        wr.release()
