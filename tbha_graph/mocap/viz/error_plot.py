"""``viz.error_plot``: per-frame error curves of a capture as a PNG (matplotlib, Agg, no pyplot).

Input: the ``errors`` bundle of ``evaluate.metrics`` (per-frame arrays, NaN where unavailable).
With ground truth: top panel, 3D joint error in mm (``mpjpe_mm`` after the clip alignment, and
``pa_mpjpe_mm`` dashed); bottom panel, 2D error in px (``error_2d_px``, tracked points vs truth; dotted,
``placed_2d_px``, the points the tracker placed without seeing them) and the reprojection error in px
(``reprojection_px``, 3D motion projected vs tracks). Without ground truth
(``mpjpe_mm`` all NaN): one panel, the reprojection error. The x axis is time in seconds (frame / fps);
each legend entry gives the curve's mean over frames — for the 3D curves exactly ``metrics.json``'s
``mpjpe_mm`` / ``pa_mpjpe_mm`` (every frame has all 16 joints); the 2D curves' means are named as such
(``metrics.json`` gives medians and 95th percentiles over the points for those). Gaps (NaN) are left as breaks in the curves. Frames whose
labelling is doubtful (``doubtful`` in the bundle, see :mod:`tbha_graph.mocap.evaluate.doubtful`) are
shaded orange in every panel.
"""
from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node
from ..ports import ERRORS, IMAGE
from . import style
from ...core.figure import new_figure, save_png


class ErrorPlotParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    title: str = Field("", description="title above the plot (default: a description of what is shown)")
    dpi: int = Field(120, ge=50, le=400, description="resolution of the PNG", json_schema_extra={"unit": "dots/inch"})


def legend_label(label: str, y: np.ndarray, unit: str) -> str:
    """A curve's legend entry: its name and its mean over frames (NaN frames left out)."""
    return f"{label} (mean over frames {float(np.nanmean(y)):.3g} {unit})"


def _curve(ax, t: np.ndarray, y: np.ndarray, label: str, unit: str, color, **kw) -> bool:
    """Plot ``y`` against ``t`` labelled with its mean; False (nothing drawn) when ``y`` is all NaN."""
    if not np.isfinite(y).any():
        return False
    ax.plot(t, y, color=style.rgb(color), lw=1.2, label=legend_label(label, y, unit), **kw)
    return True


def plot_errors(errors: dict, path, title: str = "", dpi: int = 120):
    """Draw the curves of ``errors`` (see module docstring) into a PNG at ``path``; returns the path."""
    fps = float(np.asarray(errors.get("fps", 1.0)))
    series = {k: np.asarray(errors[k], dtype=np.float64).reshape(-1) for k in ("mpjpe_mm", "error_2d_px", "reprojection_px")}
    n = series["reprojection_px"].shape[0]
    if any(v.shape[0] != n for v in series.values()) or n == 0:
        raise NodeError(f"errors: per-frame arrays have lengths { {k: v.shape[0] for k, v in series.items()} }, expected one length > 0",
                        hint="connect the 'errors' output of evaluate.metrics")
    t = np.arange(n) / fps
    has_truth = bool(np.isfinite(series["mpjpe_mm"]).any())
    fig = new_figure(9.0, 6.0 if has_truth else 3.6)
    axes = fig.subplots(2 if has_truth else 1, 1, sharex=True, squeeze=False)[:, 0]
    if has_truth:
        ax3 = axes[0]
        _curve(ax3, t, series["mpjpe_mm"], "MPJPE, clip-aligned", "mm", style.ERROR3D_BGR)
        if "pa_mpjpe_mm" in errors:
            _curve(ax3, t, np.asarray(errors["pa_mpjpe_mm"], dtype=np.float64).reshape(-1), "PA-MPJPE, per-frame aligned",
                   "mm", style.ERROR3D_BGR, ls="--")
        ax3.set_ylabel("3D joint error (mm)")
        ax3.set_title("3D: mean error of the 16 joints vs ground truth", fontsize=10, loc="left")
    ax2 = axes[-1]
    drew = _curve(ax2, t, series["error_2d_px"], "2D tracks vs ground truth", "px", style.TRACKS_PLOT_BGR)
    if "placed_2d_px" in errors:  # untracked points: the tracker's guesses, which the solver does not fit
        drew |= _curve(ax2, t, np.asarray(errors["placed_2d_px"], dtype=np.float64).reshape(-1),
                       "placed, not tracked (unused by the solve)", "px", style.TRACKS_PLOT_BGR, ls=":")
    drew |= _curve(ax2, t, series["reprojection_px"], "reprojection (3D motion vs tracks)", "px", style.REPROJECTED_BGR)
    if not drew:
        ax2.text(0.5, 0.5, "no 2D error available (no tracked joints)", transform=ax2.transAxes, ha="center", va="center")
    ax2.set_ylabel("2D error (px)")
    ax2.set_title("2D: mean pixel error of the frame's joints", fontsize=10, loc="left")
    ax2.set_xlabel(f"time (s) — {n} frames at {fps:.4g} fps")
    doubt = np.asarray(errors.get("doubtful", np.zeros(n)), dtype=np.float64).reshape(-1)
    if doubt.shape == (n,) and (doubt > 0).any():
        edges = np.diff(np.concatenate([[0], (doubt > 0).astype(np.int8), [0]]))  # runs of doubtful frames
        for k, (first, last) in enumerate(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1)):
            for ax in axes:  # a run covers its frames' whole intervals
                ax.axvspan((first - 0.5) / fps, (last + 0.5) / fps, color=style.rgb(style.DOUBTFUL_BGR), alpha=0.18, lw=0,
                           label="doubtful frames (doubtful_ranges)" if (k == 0 and ax is axes[0]) else None)
    for ax in axes:
        ax.set_xlim(0.0, max(t[-1], 1.0 / fps))
        ax.set_ylim(bottom=0.0)
        ax.grid(True, alpha=0.3)
        if ax.lines or ax.patches:
            ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(title or ("Per-frame error of the capture" if has_truth else "Per-frame reprojection error (no ground truth)"))
    return save_png(fig, path, dpi)


@node("viz.error_plot", version=2, inputs={"errors": ERRORS}, outputs={"png": IMAGE},
      params=ErrorPlotParams)
def error_plot(ctx, errors):
    """Plot the per-frame errors of evaluate.metrics: 3D error (mm) and 2D error (px) over time, or the
    reprojection error alone when there is no ground truth."""
    p: ErrorPlotParams = ctx.params
    return {"png": plot_errors(errors, ctx.output_path("errors.png"), p.title, p.dpi)}
