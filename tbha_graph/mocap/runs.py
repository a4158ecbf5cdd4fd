"""Runs of frames: where a per-frame condition holds for consecutive frames (one definition for every stage)."""
from __future__ import annotations

import numpy as np


def runs_of(mask: np.ndarray, min_len: int = 2) -> list[np.ndarray]:
    """Runs ``[frames, ...]`` (each an index array) of consecutive True frames of ``mask`` ``(n,)`` at least
    ``min_len`` long."""
    m = np.r_[False, np.asarray(mask, bool), False].astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return [np.arange(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_len]


def runs_text(runs: list[np.ndarray], first_frame: int = 0) -> str:
    """``"12-40, 97-130"``: the runs' first and last frame numbers (``first_frame`` added: the video's own
    numbering), for messages."""
    return ", ".join(f"{int(r[0]) + first_frame}-{int(r[-1]) + first_frame}" for r in runs)
