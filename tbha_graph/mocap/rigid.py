"""Weighted least-squares alignment of point sets (Kabsch / Umeyama): the project's one implementation.

:func:`procrustes` finds ``s``, ``R``, ``t`` minimising ``sum_k w_k |s R src_k + t - dst_k|^2``, batched
over leading axes (frames), with ``R`` always a proper rotation (det +1, reflections removed). It serves
the rigid fit of a joint group (``filter.fill_gaps``), the rotation of a joint's child offsets about
the joint (``rotations.kabsch``, ``center=False``) and the rigid / similarity alignment of the error
measures (:func:`tbha_graph.mocap.evaluate.measures.similarity_fit`). Units: those of the points
(metres in the pipeline); ``s`` is unit-free.
"""
from __future__ import annotations

import numpy as np


def procrustes(
    src: np.ndarray, dst: np.ndarray, w: np.ndarray | None = None, *, scale: bool = False, center: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted alignment ``dst ~ s * R @ src + t``.

    ``src``, ``dst``: ``(..., m, 3)`` (broadcast against each other); ``w``: ``(..., m)`` non-negative
    weights (None: all 1; give 0 for points to leave out, which must then be finite). ``scale``: fit
    ``s`` (Umeyama), else ``s = 1`` (Kabsch). ``center``: fit the translation ``t``; without it
    ``t = 0`` and ``R`` rotates about the origin.

    Returns ``s`` ``(...)``, ``R`` ``(..., 3, 3)`` (det +1), ``t`` ``(..., 3)``. Degenerate inputs (fewer
    than 3 weighted points, all at one place) give some rotation, not NaN: callers that care check that.
    """
    src, dst = np.broadcast_arrays(np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64))
    w = np.ones(src.shape[:-1]) if w is None else np.broadcast_to(np.asarray(w, dtype=np.float64), src.shape[:-1])
    total = np.maximum(w.sum(-1), np.finfo(float).tiny)[..., None]  # (..., 1)
    if center:
        mu_s = np.einsum("...m,...mi->...i", w, src) / total
        mu_d = np.einsum("...m,...mi->...i", w, dst) / total
    else:
        mu_s = np.zeros(src.shape[:-2] + (3,))
        mu_d = np.zeros(dst.shape[:-2] + (3,))
    cs = src - mu_s[..., None, :]
    cd = dst - mu_d[..., None, :]
    cov = np.einsum("...m,...mi,...mj->...ij", w, cd, cs)  # (..., 3, 3) dst x src
    U, S, Vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones(S.shape)
    D[..., 2] = d
    R = U @ (D[..., :, None] * Vt)
    if scale:
        var_s = np.einsum("...m,...mi,...mi->...", w, cs, cs)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (S * D).sum(-1) / var_s
    else:
        s = np.ones(S.shape[:-1])
    t = mu_d - s[..., None] * np.einsum("...ij,...j->...i", R, mu_s)
    return s, R, t
