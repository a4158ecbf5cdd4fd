"""The verdict of a capture: ``ok``, ``doubtful`` or ``failed``, with the reasons, from figures that
need no ground truth (so an own take gets one too).

``failed``: the result is not usable as it is. ``doubtful``: usable, but look at the overlay and the
reasons first. Warnings of any node make a verdict at least ``doubtful`` (the framework adds those of
other nodes when it writes ``metrics.json``: :meth:`tbha_graph.core.scheduler.RunResult.with_warnings`).
"""
from __future__ import annotations

import math
from typing import Any

#: (key, limit, what it means) -- beyond the limit the capture FAILS
FAILED_ABOVE = (("reprojection_px_median", 15.0, "the 3D motion does not reproject onto the tracked points"),
                ("missing_pct", 50.0, "most joint positions are missing"))
FAILED_BELOW = (("tracked_pct", 50.0, "fewer than half of the joints were tracked"),
                ("frames", 10, "too few frames"))
#: beyond these the capture is DOUBTFUL
DOUBTFUL_ABOVE = (("reprojection_px_median", 6.0, "reprojection error is high"),
                  ("bone_length_cv_pct", 5.0, "bone lengths vary over the take"),
                  ("inferred_pct", 20.0, "many joints were inferred, not seen"),
                  ("focal_sd_pct", 10.0, "the focal length is uncertain"),
                  ("floor_penetration_mm", 50.0, "the feet go through the floor"))
DOUBTFUL_BELOW = (("tracked_pct", 90.0, "tracking lost joints often"),)


def _num(metrics: dict[str, Any], key: str) -> float | None:
    v = metrics.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def verdict(metrics: dict[str, Any]) -> tuple[str, list[str]]:
    """``(verdict, reasons)`` for a flat metrics dict; missing figures are not judged."""
    failed, doubtful = [], []
    for key, limit, what in FAILED_ABOVE:
        v = _num(metrics, key)
        if v is not None and (not math.isfinite(v) or v > limit):
            failed.append(f"{what}: {key} = {v:.4g} > {limit:g}")
    for key, limit, what in FAILED_BELOW:
        v = _num(metrics, key)
        if v is not None and (not math.isfinite(v) or v < limit):
            failed.append(f"{what}: {key} = {v:.4g} < {limit:g}")
    for key, limit, what in DOUBTFUL_ABOVE:
        v = _num(metrics, key)
        if v is not None and (not math.isfinite(v) or v > limit):
            doubtful.append(f"{what}: {key} = {v:.4g} > {limit:g}")
    for key, limit, what in DOUBTFUL_BELOW:
        v = _num(metrics, key)
        if v is not None and (not math.isfinite(v) or v < limit):
            doubtful.append(f"{what}: {key} = {v:.4g} < {limit:g}")
    for w in metrics.get("warnings") or []:
        doubtful.append(f"warning: {w}")
    if failed:
        return "failed", failed
    return ("doubtful", doubtful) if doubtful else ("ok", [])
