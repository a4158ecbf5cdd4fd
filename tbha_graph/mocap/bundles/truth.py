"""The ``truth`` port: a rendered video's ground truth, and reading it. ``{}`` means "no ground truth"
(a user's own video): every reader returns None or skips the figures that need it.

Keys, units and frames are documented in :mod:`tbha_graph.mocap.synth.groundtruth`. Required:
``joints3d_world`` (n, 16, 3) metres world frame and ``fps`` (); checked when present: ``joints3d_cam``
(n, 16, 3) m, ``joints2d`` (n, 16, 2) px, ``patch_centers_world`` (n, 15, 3) m, ``patch2d`` (n, 15, 2) px,
``patch_visible`` (n, 15) bool, ``K``/``R`` (3, 3), ``t`` (3,), ``width``/``height`` () px,
``joint_names`` (16,) (the skeleton's joint order).
"""
from __future__ import annotations

import numpy as np

from ...core.errors import NodeError
from ..skeleton import JOINT_NAMES, N_JOINTS, N_PATCHES, PATCHED_JOINTS

REQUIRED_KEYS = ("joints3d_world", "fps")
#: per-frame keys and their shape after the frame axis
PER_FRAME_SHAPES: dict[str, tuple[int, ...]] = {
    "joints3d_world": (N_JOINTS, 3),
    "joints3d_cam": (N_JOINTS, 3),
    "joints2d": (N_JOINTS, 2),
    "patch_centers_world": (N_PATCHES, 3),
    "patch2d": (N_PATCHES, 2),
    "patch_visible": (N_PATCHES,),
}
FIXED_SHAPES: dict[str, tuple[int, ...]] = {"K": (3, 3), "R": (3, 3), "t": (3,), "fps": (), "width": (), "height": ()}


def check_ground_truth(truth: dict[str, np.ndarray], name: str = "ground truth") -> dict[str, np.ndarray]:
    """Check a ground-truth bundle (keys and shapes in the module docstring); returns it with float64
    positions. Raises :class:`NodeError` naming ``name`` and the missing or malformed keys."""
    missing = [k for k in REQUIRED_KEYS if k not in truth]
    if missing:
        raise NodeError(f"{name}: missing key(s) {missing}; present: {sorted(truth)}",
                        hint="a ground truth needs at least joints3d_world (n, 16, 3) metres and fps")
    n = np.shape(truth["joints3d_world"])[0] if np.ndim(truth["joints3d_world"]) else 0
    bad = []
    for k, tail in PER_FRAME_SHAPES.items():
        if k in truth and np.shape(truth[k]) != (n, *tail):
            bad.append(f"{k} has shape {np.shape(truth[k])}, expected {(n, *tail)}")
    for k, shape in FIXED_SHAPES.items():
        if k in truth and np.shape(truth[k]) != shape:
            bad.append(f"{k} has shape {np.shape(truth[k])}, expected {shape}")
    if bad:
        raise NodeError(f"{name}: " + "; ".join(bad), hint="the file does not follow tbha_graph.mocap.synth.groundtruth")
    if n == 0:
        raise NodeError(f"{name}: joints3d_world has no frames")
    fps = float(truth["fps"])
    if not (np.isfinite(fps) and fps > 0):
        raise NodeError(f"{name}: fps is {fps}, expected a positive number of frames per second")
    if "joint_names" in truth and tuple(str(s) for s in np.asarray(truth["joint_names"]).reshape(-1)) != JOINT_NAMES:
        raise NodeError(f"{name}: joint_names {list(np.asarray(truth['joint_names']).reshape(-1))} differ from the skeleton's {list(JOINT_NAMES)}",
                        hint="reorder the joints to tbha_graph.mocap.skeleton.JOINT_NAMES")
    out = dict(truth)
    for k in ("joints3d_world", "joints3d_cam", "joints2d"):
        if k in out:
            out[k] = np.asarray(out[k], dtype=np.float64)
    if "patch_visible" in out:
        out["patch_visible"] = np.asarray(out["patch_visible"], dtype=bool)
    return out


def truth_joints2d(truth: dict[str, np.ndarray], width: int | None = None, height: int | None = None) -> np.ndarray | None:
    """The truth's ``joints2d`` ``(n, 16, 2)`` pixels, rescaled to a ``width`` x ``height`` image when the
    truth was rendered at another size (``io.video``'s ``scale``); pixel centres stay at integers.
    ``None`` when the truth has no ``joints2d``."""
    if "joints2d" not in truth:
        return None
    p = np.asarray(truth["joints2d"], dtype=np.float64)
    if width is None or height is None or "width" not in truth or "height" not in truth:
        return p
    sx = float(width) / float(truth["width"])
    sy = float(height) / float(truth["height"])
    if sx == 1.0 and sy == 1.0:
        return p
    return (p + 0.5) * np.array([sx, sy]) - 0.5


def truth_visibility(truth: dict[str, np.ndarray]) -> np.ndarray | None:
    """Which joints the camera sees, ``(n, 16)`` bool: a patched joint when its patch is visible
    (``patch_visible``); the head (no patch: the hair is its dark "patch") when its projection lies in
    the image. Without ``patch_visible``, every joint projected inside the image. ``None`` without ``joints2d``."""
    if "joints2d" not in truth:
        return None
    p = np.asarray(truth["joints2d"], dtype=np.float64)
    inside = np.isfinite(p).all(-1)
    if "width" in truth and "height" in truth:
        w, h = float(truth["width"]), float(truth["height"])
        inside &= (p[..., 0] >= -0.5) & (p[..., 0] <= w - 0.5) & (p[..., 1] >= -0.5) & (p[..., 1] <= h - 0.5)
    if "patch_visible" not in truth:
        return inside
    vis = inside.copy()
    patched = [JOINT_NAMES.index(n) for n in PATCHED_JOINTS]
    vis[:, patched] = np.asarray(truth["patch_visible"], dtype=bool)
    return vis
