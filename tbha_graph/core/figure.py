"""Saving a matplotlib figure as a PNG atomically (temporary file in the same folder, then rename)."""
from __future__ import annotations

from pathlib import Path

from .atomic import atomic_path


def save_png(fig, path: str | Path, dpi: int) -> Path:
    """Write ``fig`` (a ``matplotlib.figure.Figure``) to ``path`` as PNG at ``dpi``; nothing is left
    at ``path`` if saving fails."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def new_figure(width_in: float, height_in: float, constrained: bool = True):
    """A matplotlib ``Figure`` drawn with Agg, without pyplot's global state (safe in worker threads).
    ``constrained``: matplotlib's constrained layout (neat, but about 50 ms per axes to compute)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained" if constrained else None)
    FigureCanvasAgg(fig)
    return fig
