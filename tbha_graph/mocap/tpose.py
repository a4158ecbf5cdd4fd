"""Finding the opening T-pose of a take in its 2D joint tracks.

Everything the pipeline does first -- telling same-coloured patches apart, fitting the camera, measuring
bones -- assumes the take opens with the actor in a T-pose facing the camera, and the whole-take solver holds
the limbs to a T-pose on the frames found here (``sigma_tpose``). A take without one must
fail clearly rather than give confident-looking figures. :func:`find_tpose` looks for it in the first
seconds: a run of frames where, in the image (pixels, y down; L = the 2D neck-hips length),

* the body is upright: neck above hips, nearly vertically;
* it faces the camera: the actor's left shoulder is on the image's right, shoulders at least 0.3 L apart;
* the arms are level and out: elbows and wrists within ``level`` × L of shoulder height, wrists at least
  ``reach`` × L beyond the shoulders, outwards on both sides;
* the legs are straight: hip-knee-ankle bent less than ``max_knee_deg``, ankles below knees below hips.
"""
from __future__ import annotations

import numpy as np

from .skeleton import JOINT_INDEX as J

NEEDED = ("neck", "hips", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
          "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")


def tpose_frames(points: np.ndarray, tracked: np.ndarray, level: float = 0.3, reach: float = 0.6,
                 max_knee_deg: float = 30.0, max_untracked: int = 0) -> np.ndarray:
    """(n_frames,) bool: frames whose 2D joints show a T-pose facing the camera (criteria above); up to
    ``max_untracked`` of the needed joints may be the tracker's estimates instead of seen patches."""
    p = np.asarray(points, dtype=np.float64)
    seen = np.asarray(tracked, dtype=bool)[:, [J[j] for j in NEEDED]].sum(axis=1)
    ok = (seen >= len(NEEDED) - max_untracked) & np.isfinite(p).all(axis=(1, 2))
    x, y = p[..., 0], p[..., 1]
    L = np.linalg.norm(p[:, J["neck"]] - p[:, J["hips"]], axis=1)
    L = np.where(L > 1e-6, L, np.nan)
    with np.errstate(invalid="ignore"):
        upright = (y[:, J["neck"]] < y[:, J["hips"]]) & (np.abs(x[:, J["neck"]] - x[:, J["hips"]]) < 0.35 * L)
        facing = (x[:, J["left_shoulder"]] - x[:, J["right_shoulder"]]) > 0.3 * L
        arms = np.ones(len(p), dtype=bool)
        for side, sign in (("left", 1.0), ("right", -1.0)):
            sh, el, wr = J[f"{side}_shoulder"], J[f"{side}_elbow"], J[f"{side}_wrist"]
            arms &= np.abs(y[:, el] - y[:, sh]) < level * L
            arms &= np.abs(y[:, wr] - y[:, sh]) < level * L
            arms &= sign * (x[:, wr] - x[:, sh]) > reach * L
            arms &= sign * (x[:, wr] - x[:, el]) > 0
            arms &= sign * (x[:, el] - x[:, sh]) > 0
        legs = np.ones(len(p), dtype=bool)
        for side in ("left", "right"):
            hip, kn, an = p[:, J[f"{side}_hip"]], p[:, J[f"{side}_knee"]], p[:, J[f"{side}_ankle"]]
            a, b = kn - hip, an - kn
            cos = (a * b).sum(axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-12)
            legs &= np.degrees(np.arccos(np.clip(cos, -1, 1))) < max_knee_deg
            legs &= (kn[:, 1] > hip[:, 1]) & (an[:, 1] > kn[:, 1])
    return ok & upright & facing & arms & legs


def find_tpose(points: np.ndarray, tracked: np.ndarray, fps: float, seconds: float = 3.0, hold_seconds: float = 0.2,
               **criteria) -> tuple[int, int] | None:
    """The first run of T-pose frames ``(first, last)`` (inclusive) lasting at least ``hold_seconds`` and
    starting within the first ``seconds`` of the take; None when there is none."""
    good = tpose_frames(points, tracked, **criteria)
    n_search = min(len(good), max(1, int(round(seconds * fps))))
    hold = max(1, int(round(hold_seconds * fps)))
    run_start = None
    for i in range(len(good)):
        if good[i]:
            if run_start is None:
                if i >= n_search:
                    return None
                run_start = i
            if i - run_start + 1 >= hold:
                end = i
                while end + 1 < len(good) and good[end + 1]:
                    end += 1
                return run_start, end
        else:
            run_start = None
    return None
