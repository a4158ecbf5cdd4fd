"""A study's figures as a picture: ``results.png`` beside ``results.md``, one panel per figure (metric column).

In each panel every variant has a row, in the study's order, with one bar per input (one colour per input, the
legend naming them); the bar's value is written at its end. A variant that failed on an input has no bar but the
word "failed" where it would start; a figure one run did not produce leaves its bar out. Panels share nothing but
the rows' order, so figures of different units (mm, px, degrees) sit side by side, each on its own scale.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from .figure import new_figure, save_png

#: table columns that describe the run, not the variant's result: never charted (wall_s counts cache hits too)
NOT_FIGURES = frozenset({"variant", "input", "status", "error", "wall_s", "ran", "cached"})
#: panels side by side before a new row of panels starts
PANELS_PER_ROW = 3


def _number(v: Any) -> float | None:
    """``v`` as a finite float, or None (booleans and text are not figures)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def chart_columns(rows: list[dict[str, Any]], columns: list[str] | None = None) -> list[str]:
    """The figures charted: the study's ``columns`` when it names them, else every column holding a number in
    some row (in the order the rows first show them), the run's bookkeeping (:data:`NOT_FIGURES`) left out."""
    names: list[str] = []
    for r in rows:
        for k in r:
            if k not in names:
                names.append(k)
    wanted = [str(c) for c in columns] if columns else names
    return [c for c in wanted if c not in NOT_FIGURES and any(_number(r.get(c)) is not None for r in rows)]


def chart_bars(rows: list[dict[str, Any]], column: str) -> tuple[list[str], list[str], dict[tuple[str, str], float | str]]:
    """``(variants, inputs, bars)`` of one panel: variants and inputs in the rows' order, and per
    ``(variant, input)`` the figure, or ``"failed"`` for a run that failed (pairs without the figure left out)."""
    variants = list(dict.fromkeys(str(r.get("variant")) for r in rows))
    inputs = list(dict.fromkeys(str(r.get("input")) for r in rows))
    bars: dict[tuple[str, str], float | str] = {}
    for r in rows:
        key = (str(r.get("variant")), str(r.get("input")))
        if r.get("status") == "failed":
            bars[key] = "failed"
        elif (v := _number(r.get(column))) is not None:
            bars[key] = v
    return variants, inputs, bars


def write_chart(rows: list[dict[str, Any]], out_dir: Path, columns: list[str] | None = None, title: str = "",
                stem: str = "results") -> Path | None:
    """``<stem>.png`` under ``out_dir`` (written atomically) charting :func:`chart_columns`. When no row holds a
    figure (every run failed, or the study's pipeline gives no numbers) the picture says so, so that a picture left
    by an earlier run of the study is never shown as this one's."""
    cols = chart_columns(rows, columns)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    if not cols:
        fig = new_figure(6.0, 1.2)
        failed = sum(r.get("status") == "failed" for r in rows)
        fig.text(0.5, 0.5, f"{title}\nno figures to draw: {failed} of {len(rows)} runs failed (results.md has the errors)",
                 ha="center", va="center", fontsize=9)
        return save_png(fig, Path(out_dir) / f"{stem}.png", dpi=110)
    variants, inputs, _ = chart_bars(rows, cols[0])
    n_bars = len(variants) * len(inputs)
    per_row = min(PANELS_PER_ROW, len(cols))
    n_rows = math.ceil(len(cols) / per_row)
    panel_h = 0.9 + 0.24 * n_bars + 0.12 * len(variants)
    fig = new_figure(1.6 + 3.1 * per_row, 0.5 + panel_h * n_rows + (0.3 if len(inputs) > 1 else 0.0))
    colours = [f"C{i % 10}" for i in range(len(inputs))]
    height = 0.8 / len(inputs)
    for p, col in enumerate(cols):
        ax = fig.add_subplot(n_rows, per_row, p + 1)
        _, _, bars = chart_bars(rows, col)
        values = [v for v in bars.values() if not isinstance(v, str)]
        span = max((abs(v) for v in values), default=1.0) or 1.0
        for vi, variant in enumerate(variants):
            for ii, inp in enumerate(inputs):
                y = vi + (ii - (len(inputs) - 1) / 2) * height
                v = bars.get((variant, inp))
                if v is None:
                    continue
                if isinstance(v, str):
                    ax.text(0.0, y, " failed", va="center", ha="left", fontsize=7, color="#b00020")
                    continue
                ax.barh(y, v, height=height * 0.9, color=colours[ii])
                ax.text(v, y, f" {v:.4g}", va="center", ha="left" if v >= 0 else "right", fontsize=7)
        ax.set_yticks(range(len(variants)), variants if p % per_row == 0 else [""] * len(variants), fontsize=8)
        ax.set_ylim(len(variants) - 0.5, -0.5)  # the study's first variant at the top, as in the table
        lo = min(0.0, min(values, default=0.0))
        ax.set_xlim(lo - 0.28 * span if lo < 0 else 0.0, max(0.0, max(values, default=0.0)) + 0.28 * span)
        ax.axvline(0.0, color="0.3", linewidth=0.6)
        ax.set_title(col, fontsize=9)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(axis="x", alpha=0.3)
    if len(inputs) > 1:  # one swatch per input, whichever runs failed
        from matplotlib.patches import Patch

        fig.legend(handles=[Patch(color=c, label=inp) for c, inp in zip(colours, inputs)], loc="outside lower center",
                   ncols=min(len(inputs), 6), fontsize=8, title="input", title_fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_png(fig, Path(out_dir) / f"{stem}.png", dpi=110)
