"""Where a detector's keypoints sit relative to this project's joint centres, fitted on renders.

MediaPipe's "left_hip" is not the CMU skeleton's hip joint centre, its "left_shoulder" not our shoulder
joint: each landmark sits somewhere on or in the body near the joint, and how far off differs per joint. The
whole-take solver models every tracked point as its joint moved by an offset in the body frame
(:func:`tbha_graph.mocap.reconstruct.take_model.point_positions`): ``along`` the limb axis through the joint
and ``out`` of the body's front (metres). This module fits those two numbers per joint from renders whose
true 3D joints and camera are known, and reads the fitted table shipped with the project
(``mediapipe_offsets.json`` beside this file, written by ``python bench/mediapipe_offsets_fit.py``, which
records how it was fitted: renders, frames, residuals before and after).

The fit is linear: a point ``X + a·axis + b·out`` seen at pixel ``(u, v)`` by a camera of focal ``f`` and
centre ``(cx, cy)`` satisfies ``(u - cx)·Z' = f·X'`` and ``(v - cy)·Z' = f·Y'`` (primes: the moved point),
linear in ``(a, b)``. Left and right joints share their offsets (the body is mirror symmetric; both
components are mirror invariant). Observations more than 3 median residuals off are dropped (twice).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...core.errors import NodeError
from ..skeleton import JOINT_NAMES, N_JOINTS

OFFSETS_FILE = Path(__file__).with_name("mediapipe_offsets.json")


def body_axes(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The solver's ``axis`` and ``out`` unit vectors ``(n, 16, 3)`` for joints ``P`` ``(n, 16, 3)``."""
    from ..reconstruct.take_model import point_positions

    # point_positions is linear in the offsets: the unit offsets give the two directions exactly as the solver uses them
    z = np.zeros((N_JOINTS, 2))
    e1, e2 = z.copy(), z.copy()
    e1[:, 0], e2[:, 1] = 1.0, 1.0
    return point_positions(P, e1) - P, point_positions(P, e2) - P


def _mirror_key(name: str) -> str:
    return name.replace("left_", "side_").replace("right_", "side_")


def fit_point_offsets(P_cam: list[np.ndarray], K: list[np.ndarray], observed: list[np.ndarray],
                      tracked: list[np.ndarray]) -> tuple[np.ndarray, dict]:
    """Offsets ``(16, 2)`` (along, out) metres fitted over takes (lists: true camera-frame joints ``(n, 16, 3)``,
    intrinsics ``(3, 3)``, observed points ``(n, 16, 2)`` px, tracked ``(n, 16)`` bool) and per joint
    ``{"observations", "px_median_before", "px_median_after"}`` (median per-axis residual, pixels)."""
    rows: dict[str, list] = {}
    for P, k, obs, tr in zip(P_cam, K, observed, tracked):
        axis, out = body_axes(P)
        f, cx, cy = k[0, 0], k[0, 2], k[1, 2]
        for j, name in enumerate(JOINT_NAMES):
            m = tr[:, j] & np.isfinite(obs[:, j]).all(-1) & np.isfinite(P[:, j]).all(-1)
            if not m.any():
                continue
            B = np.stack([axis[m, j], out[m, j]], axis=-1)  # (k, xyz, 2)
            X, u, v = P[m, j], obs[m, j, 0] - cx, obs[m, j, 1] - cy
            A = np.concatenate([f * B[:, 0] - u[:, None] * B[:, 2], f * B[:, 1] - v[:, None] * B[:, 2]])
            b = np.concatenate([u * X[:, 2] - f * X[:, 0], v * X[:, 2] - f * X[:, 1]])
            depth = np.concatenate([X[:, 2], X[:, 2]])
            rows.setdefault(_mirror_key(name), []).append((A, b, depth))
    offsets = np.zeros((N_JOINTS, 2))
    stats: dict = {}
    for key, parts in rows.items():
        A = np.concatenate([p[0] for p in parts])
        b = np.concatenate([p[1] for p in parts])
        depth = np.concatenate([p[2] for p in parts])
        keep = np.ones(b.size, dtype=bool)
        o = np.zeros(2)
        for _ in range(3):
            o, *_ = np.linalg.lstsq(A[keep], b[keep], rcond=None)
            r = np.abs(A @ o - b) / depth
            keep = r <= 3.0 * np.median(r) + 1e-9
        for j, name in enumerate(JOINT_NAMES):
            if _mirror_key(name) == key:
                offsets[j] = o
                stats[name] = {"observations": int(b.size // 2), "px_median_before": round(float(np.median(np.abs(b) / depth)), 3),
                               "px_median_after": round(float(np.median(np.abs(A @ o - b) / depth)), 3)}
    return offsets, stats


def load_mediapipe_offsets(path: str | Path = OFFSETS_FILE) -> np.ndarray:
    """The fitted MediaPipe landmark offsets ``(16, 2)`` (along, out) metres, joint order, from ``path``."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        table = doc["offsets_m"]
        offs = np.array([[float(table[n]["along"]), float(table[n]["out"])] for n in JOINT_NAMES])
    except FileNotFoundError:
        raise NodeError(f"the MediaPipe landmark offsets file {path} is missing",
                        hint="reinstall the project, or refit it: python bench/mediapipe_offsets_fit.py; "
                             "or run with --set detect.offsets=none") from None
    except (ValueError, KeyError, TypeError) as e:
        raise NodeError(f"{path}: not a landmark offsets table ({type(e).__name__}: {e})",
                        hint="expected {'offsets_m': {joint: {'along': m, 'out': m}, ...}} for all 16 joints; "
                             "refit it: python bench/mediapipe_offsets_fit.py") from None
    if not np.isfinite(offs).all() or np.abs(offs).max() > 0.3:
        raise NodeError(f"{path}: offsets must be finite and within 0.3 m", hint="refit: python bench/mediapipe_offsets_fit.py")
    return offs
