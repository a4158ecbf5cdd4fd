"""``color.hsv``: the suit's colours in HSV, as colour-wheel coordinates (S cos H, S sin H). An alternative to rg chromaticity."""
from __future__ import annotations

from ...core.node import node, optional
from ..ports import COLORS, SUIT
from .model import ColorParams, color_model_node


@node("color.hsv", version=1, inputs={"suit": optional(SUIT, "suit spec (default: the 'suit' param)")},
      outputs={"model": COLORS}, params=ColorParams)
def hsv(ctx, suit=None) -> dict:
    """Suit colours as reference points and tolerances in the hsv chroma plane, plus the dark-head and
    white-suit classes (see tbha_graph.mocap.color.model)."""
    return color_model_node(ctx, suit, "hsv")
